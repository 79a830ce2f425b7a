"""The wheel installs as it runs here (docs/architecture.md §11.1): built from the repository, installed into a fresh
environment, and run from outside the repository, it has every subpackage and every data file.

Offline: the wheel is built with the project venv's own setuptools (--no-build-isolation) from a copy of the
source, and the fresh environment borrows the project venv's third-party packages through a .pth line naming its
site-packages. A directory named in a .pth is only added to sys.path (its own .pth files are not read), so the
project's editable install of returnlink (a finder started by a .pth there) stays off: a module or data file the
wheel lacks fails here instead of being found in the work tree. The wheel is installed before that line is
written, so pip never sees the editable returnlink and never touches it.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

pytestmark = pytest.mark.interop

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("vehicle", "gcs", "link", "sim")
# what the build does not need and must not see: caches, build leftovers (a stale build/lib lands in the wheel),
# run outputs, the repository and the venv
NOT_COPIED = shutil.ignore_patterns(".git", ".venv", "build", "dist", "*.egg-info", "__pycache__", "out",
                                    ".pytest_cache", ".ruff_cache", ".hypothesis", "*.tlog", "*.tlog.raw")

PROBE = r"""
import json, sys
from pathlib import Path
import vehicle, vehicle.companion.app, vehicle.services, sim.policies, sim.firmware, sim.campaign
from gcs.mapserver import WEB
from link import dialect
from sim import scenario
from sim.campaign.spec import load_spec
specs = Path(sim.campaign.__file__).parent / "specs"
print(json.dumps({
    "files": [m.__file__ for m in (vehicle, vehicle.companion.app, vehicle.services, sim.policies, sim.firmware)],
    "editable": [m for m in sys.modules if "editable" in m],
    "path": sys.path,
    "web": sorted(p.name for p in WEB.iterdir()),
    "dialect_xml": dialect.XML_PATH.is_file() and len(dialect.xml_hash()) == 64,
    "scenarios": [scenario.load(n).name for n in scenario.BUILTIN],
    "specs": {p.relative_to(specs).as_posix(): len(load_spec(p).trials) for p in sorted(specs.glob("*.toml"))},
    "unit": (Path(vehicle.companion.app.__file__).parent / "returnlink-companion.service").is_file(),
}))
"""


def _run(cmd: list, env: dict, cwd: Path, timeout: float = 300) -> subprocess.CompletedProcess:
    """(``timeout``: a hang guard, never a speed check; on a loaded 2-core machine importing the installed package
    once took over 60 s)"""
    r = subprocess.run([str(c) for c in cmd], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert r.returncode == 0, f"{cmd} exited {r.returncode}\n--- stdout\n{r.stdout}\n--- stderr\n{r.stderr}"
    return r


def _repo_files() -> set[str]:
    """Every file of the four packages the repository holds or would add (not the ignored ones)."""
    try:
        out = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard", "--", *PACKAGES],
                             cwd=ROOT, capture_output=True, text=True, check=True, timeout=30).stdout
    except (OSError, subprocess.SubprocessError):
        pytest.skip("git is needed to list the repository's files")
    return {f for f in out.splitlines() if (ROOT / f).is_file()}


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """(wheel, the fresh venv's bin directory, env for it, a working directory outside the repository)."""
    tmp = tmp_path_factory.mktemp("wheel")
    src, dist, venv, work = tmp / "src", tmp / "dist", tmp / "venv", tmp / "work"
    shutil.copytree(ROOT, src, ignore=NOT_COPIED)  # tests/ and benchmarks/ too: the wheel must leave them out
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-index", "-q",
          "-w", dist, src], dict(os.environ), tmp, timeout=300)
    (wheel,) = dist.glob("returnlink-*.whl")
    _run([sys.executable, "-m", "venv", "--without-pip", venv], dict(os.environ), tmp)
    bin_dir = venv / "bin"
    python = bin_dir / "python"
    _run([sys.executable, "-m", "pip", "--python", python, "install", "--no-deps", "--no-index", "-q", wheel],
         dict(os.environ), tmp, timeout=300)
    site = Path(_run([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                     {}, tmp).stdout.strip())
    ours = dict.fromkeys(sysconfig.get_paths()[k] for k in ("purelib", "platlib"))
    (site / "returnlink-test-deps.pth").write_text("".join(f"{p}\n" for p in ours), encoding="utf-8")
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV", "PYTHONSTARTUP", "PYTHONUSERBASE")}
    env["PATH"] = os.pathsep.join([str(bin_dir)] + [p for p in env.get("PATH", "").split(os.pathsep)
                                                    if p and not p.startswith(str(ROOT))])
    work.mkdir()
    return wheel, bin_dir, env, work


def test_the_wheel_holds_every_module_and_data_file_and_no_tests(installed):
    wheel = installed[0]
    names = set(zipfile.ZipFile(wheel).namelist())
    missing = sorted(_repo_files() - names)
    assert not missing, f"the wheel lacks {len(missing)} files of the repository: {missing}"
    assert "vehicle/companion/returnlink-companion.service" in names
    assert "vehicle/applet/returnlink.lua" in names  # the applet an owner copies to APM/scripts/
    assert not [n for n in names if n.split("/")[0] in ("tests", "benchmarks", "docs", "params")]
    assert not [n for n in names if "__pycache__" in n or n.endswith(".pyc")]


def test_the_installed_modules_and_data_are_the_wheels_not_the_work_tree(installed):
    _, bin_dir, env, work = installed
    venv = bin_dir.parent.resolve()
    probe = json.loads(_run([bin_dir / "python", "-c", PROBE], env, work).stdout)
    for f in probe["files"]:
        assert Path(f).resolve().is_relative_to(venv), f"{f} is not the installed one (venv {venv})"
    assert probe["editable"] == [], "the project venv's editable install is active in the fresh venv"
    assert not [p for p in probe["path"] if p and Path(p).resolve() == ROOT]
    assert {"index.html", "map.css", "map.js"} <= set(probe["web"])
    assert probe["dialect_xml"]
    assert len(probe["scenarios"]) == 7
    # every campaign spec of the package loads, worlds/ included (linkmap_seek.toml flies worlds/shrink.toml)
    assert {"companion.toml", "firmware.toml", "linkmap_seek.toml"} <= set(probe["specs"])
    assert all(n > 0 for n in probe["specs"].values()), probe["specs"]
    assert probe["unit"]


def test_the_installed_commands_run_outside_the_repository(installed):
    _, bin_dir, env, work = installed
    returnlink = bin_dir / "returnlink"
    assert returnlink.read_text(encoding="utf-8").startswith(f"#!{bin_dir / 'python'}")
    companion = _run([returnlink, "companion", "--help"], env, work).stdout
    assert "--autopilot" in companion and "--gcs" in companion and "--params" in companion
    gcs = _run([returnlink, "gcs", "--help"], env, work).stdout
    assert "--url" in gcs and "map" in gcs
    assert "spec" in _run([returnlink, "sim", "sweep", "--help"], env, work).stdout
    out = work / "tunnel"
    _run([returnlink, "sim", "run", "tunnel", "--out", out], env, work, timeout=300)
    assert json.loads((out / "metrics.json").read_text(encoding="utf-8"))["passed"] is True
