"""Signing from the command line: ``returnlink keys new``, ``sim serve --key`` and ``gcs --key``, exit codes and
messages naming the file and line, and a keyed vehicle on loopback UDP driven by a keyed and an unkeyed station."""

from __future__ import annotations

import hashlib
import os
import stat

import pytest

from link.signing import Key, SigningVerdict
from sim.cli import main
from tests.interop import ServedVehicle
from vehicle.keystore import read_key, stamp_path, write_key

pytestmark = pytest.mark.interop


def test_keys_new_writes_a_private_random_key_and_never_overwrites(tmp_path, capsys):
    path = tmp_path / "v.key"
    assert main(["keys", "new", str(path)]) == 0
    first = read_key(path)
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o600 and first.fingerprint in capsys.readouterr().out
    assert main(["keys", "new", str(path)]) == 2
    assert "--force" in capsys.readouterr().err and read_key(path) == first
    assert main(["keys", "new", str(path), "--force"]) == 0
    assert read_key(path) != first


def test_keys_new_from_a_passphrase_is_mavproxys_key(tmp_path):
    path = tmp_path / "v.key"
    assert main(["keys", "new", str(path), "--passphrase", "adit-7"]) == 0
    assert read_key(path).secret == hashlib.sha256(b"adit-7").digest()


@pytest.mark.parametrize("command", [
    lambda key: ["sim", "serve", "tunnel", "--duration", "1", "--key", key],
    lambda key: ["gcs", "--key", key, "status"],
], ids=["sim serve", "gcs"])
def test_a_damaged_or_missing_key_file_exits_2_naming_file_and_line(tmp_path, capsys, command):
    bad = tmp_path / "bad.key"
    bad.write_text("00" * 31 + "\n")
    assert main(command(str(bad))) == 2
    assert f"{bad}:1: 62 characters" in capsys.readouterr().err
    assert main(command(str(tmp_path / "none.key"))) == 2
    assert "none.key: No such file" in capsys.readouterr().err


@pytest.fixture()
def keyed_vehicle(tmp_path):
    path = tmp_path / "v.key"
    write_key(path, Key.generate())
    served = ServedVehicle("tunnel", key_file=path)
    try:
        yield served, path
    finally:
        served.close()


def test_gcs_with_the_key_flies_and_without_it_only_watches(keyed_vehicle, capsys):
    served, path = keyed_vehicle
    url = ["gcs", "--url", f"udpin:127.0.0.1:{served.gcs_port}"]
    assert main([*url, "status"]) == 0  # no key: it can watch
    assert "state NO_OWNER" in capsys.readouterr().out
    assert main([*url, "param", "set", "LNK_TIMEOUT", "5"]) == 1  # but not act
    assert main([*url, "--timeout", "3", "acquire"]) == 1
    assert served.vehicle.book.owner is None and served.vehicle.params["LNK_TIMEOUT"] == 3.0
    assert main([*url, "--key", str(path), "acquire"]) == 0
    assert main([*url, "--key", str(path), "param", "set", "LNK_TIMEOUT", "5"]) == 0
    assert served.vehicle.book.owner == 255 and served.vehicle.params["LNK_TIMEOUT"] == 5.0
    assert served.server.plant.endpoint.counters.signing[SigningVerdict.UNSIGNED] > 0
    assert served.server.plant.endpoint.counters.signing[SigningVerdict.ACCEPT] > 0
    capsys.readouterr()
    served.server.close()  # shutdown saves the signing timestamp beside the key
    assert int(stamp_path(path).read_text()) > 0


def test_gcs_with_a_key_names_an_unkeyed_vehicle(tmp_path, capsys):
    path = tmp_path / "v.key"
    write_key(path, Key.generate())
    served = ServedVehicle("tunnel")
    try:
        url = ["gcs", "--url", f"udpin:127.0.0.1:{served.gcs_port}", "--timeout", "1.5"]
        assert main([*url, "--key", str(path), "status"]) == 1
        assert "not signed with this key" in capsys.readouterr().err
    finally:
        served.close()
