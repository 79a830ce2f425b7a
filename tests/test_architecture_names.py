"""docs/architecture.md is the one layout description, and it names every module: each ``.py`` under vehicle/,
gcs/, link/ and sim/ (new ones not yet committed included) by its path (``sim/px4/serve.py``) or dotted name
(``sim.px4.serve``); a package by its folder (``sim/px4/``) or dotted name. A module added without its line fails
here, named."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "architecture.md"
ROOMS = ("vehicle", "gcs", "link", "sim")


def modules() -> list[str]:
    """Every module's path under the rooms, as git sees the tree (tracked, and new files not ignored)."""
    listed = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard", *ROOMS], cwd=ROOT,
                            capture_output=True, text=True, check=True).stdout.split()
    return sorted({name for name in listed if name.endswith(".py") and (ROOT / name).is_file()})


def names(path: str) -> tuple[str, str]:
    """How the page may name a module: its path and its dotted name (a package: its folder and dotted name)."""
    parts = path[:-3].split("/")
    if parts[-1] == "__init__":
        parts = parts[:-1]
        return "/".join(parts) + "/", ".".join(parts)
    return path, ".".join(parts)


def named(text: str, path: str) -> bool:
    slashed, dotted = names(path)
    edge = r"(?<![\w./]){}(?![\w/])"
    return any(re.search(edge.format(re.escape(n)), text) for n in (slashed, dotted))


def test_every_module_is_named_in_the_architecture_page():
    text = DOC.read_text(encoding="utf-8")
    found = modules()
    assert "vehicle/app.py" in found and "sim/px4/__init__.py" in found  # the walk itself finds modules
    missing = [path for path in found if not named(text, path)]
    assert not missing, f"docs/architecture.md names no {', '.join(missing)}: add a line for each to its §2"


def test_a_name_is_a_whole_path_not_part_of_another():
    assert named("`sim/px4/serve.py`", "sim/px4/serve.py") and named("sim.px4.serve", "sim/px4/serve.py")
    assert not named("sim/firmware/serve.py", "sim/serve.py") and not named("sim/serve.pyc", "sim/serve.py")
    assert named("sim/px4/ (PX4 in the loop)", "sim/px4/__init__.py") and not named("sim/px4/x.py", "sim/__init__.py")
