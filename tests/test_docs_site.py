"""The documentation site builds strictly (DESIGN.md §2 "Docs"): `mkdocs build --strict` over mkdocs.yml fails on a
broken link or anchor between the pages, a page of docs/ missing from the nav, or a nav entry with no page."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.interop  # a subprocess

ROOT = Path(__file__).resolve().parent.parent


def build(config: Path, site: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file", str(config),
                           "--site-dir", str(site)], cwd=ROOT, capture_output=True, text=True, timeout=300)


def test_the_docs_build_strictly(tmp_path):
    done = build(ROOT / "mkdocs.yml", tmp_path / "site")
    assert done.returncode == 0, done.stdout + done.stderr
    assert (tmp_path / "site" / "evidence" / "index.html").is_file()


def test_a_broken_link_fails_the_build(tmp_path):
    """The strictness is real: the same site with one link to a page that is not there does not build."""
    docs = tmp_path / "docs"
    docs.mkdir()
    for page in (ROOT / "docs").glob("*.md"):
        (docs / page.name).write_text(page.read_text(encoding="utf-8"), encoding="utf-8")
    (docs / "index.md").write_text((docs / "index.md").read_text() + "\n[gone](nowhere.md)\n", encoding="utf-8")
    config = tmp_path / "mkdocs.yml"
    config.write_text((ROOT / "mkdocs.yml").read_text(encoding="utf-8").replace("docs_dir: docs",
                                                                                 f"docs_dir: {docs}"))
    done = build(config, tmp_path / "site")
    assert done.returncode != 0 and "nowhere.md" in done.stdout + done.stderr
