"""Files the vehicle keeps are replaced atomically and read strictly (docs/architecture.md §8)."""

from __future__ import annotations

import os
import stat

import pytest

from link.storage import StoredFileError, read_text, write_atomic


def test_write_replaces_whole_file_and_leaves_no_temporary(tmp_path):
    target = tmp_path / "x.parm"
    write_atomic(target, "A 1\n")
    write_atomic(target, "B 2\n")
    assert target.read_text() == "B 2\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.parm"]


def test_secret_is_created_with_its_mode(tmp_path):
    target = tmp_path / "key"
    write_atomic(target, "00" * 32 + "\n", mode=0o600)
    assert stat.S_IMODE(os.stat(target).st_mode) == 0o600


def test_failed_write_keeps_the_old_file(tmp_path, monkeypatch):
    target = tmp_path / "x.parm"
    write_atomic(target, "old\n")

    def broken_fsync(fd):
        raise OSError(5, "I/O error")

    monkeypatch.setattr(os, "fsync", broken_fsync)
    with pytest.raises(OSError):
        write_atomic(target, "new\n")
    monkeypatch.undo()
    assert target.read_text() == "old\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.parm"]


def test_unreadable_file_is_named(tmp_path):
    bad = tmp_path / "bad.parm"
    bad.write_bytes(b"\xff\xfe\x00")
    with pytest.raises(StoredFileError, match="bad.parm"):
        read_text(bad)
    with pytest.raises(StoredFileError, match="missing.parm"):
        read_text(tmp_path / "missing.parm")
