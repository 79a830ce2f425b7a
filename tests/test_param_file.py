"""Nothing is lost on a crash (docs/architecture.md §8): the vehicle's .parm is replaced atomically and read strictly at
boot."""

from __future__ import annotations

import os
import random
import subprocess
import sys
import time
from pathlib import Path

import pytest

from link.storage import StoredFileError, remove_leftovers
from sim.cli import main
from vehicle.params import SPECS, read_parm_file

pytestmark = pytest.mark.interop

# Saves the parameter file as the endpoint does on every accepted PARAM_SET, as fast as it can, alternating
# two values; prints "saved" once the first save is on disk.
HAMMER = """
import sys
from pathlib import Path
from vehicle.params import Params, save_parm
path, params = Path(sys.argv[1]), Params()
n = 0
while True:
    params.set("RTL_MAX_DISP", 60.0 + n % 2)
    save_parm(path, params.values)
    if n == 0:
        print("saved", flush=True)
    n += 1
"""


def _hammer(path: Path) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parent.parent))
    proc = subprocess.Popen([sys.executable, "-c", HAMMER, str(path)], stdout=subprocess.PIPE, text=True, env=env)
    assert proc.stdout is not None and proc.stdout.readline().strip() == "saved"
    return proc


def _complete(path: Path) -> dict[str, float]:
    values = read_parm_file(path)  # StoredFileError if empty or cut short
    assert set(values) == {s.name for s in SPECS}
    assert values["RTL_MAX_DISP"] in (60.0, 61.0)
    return values


def test_sigkill_during_saves_always_leaves_a_complete_parm_file(tmp_path):
    path = tmp_path / "vehicle.parm"
    rng = random.Random(9)
    for _ in range(6):
        proc = _hammer(path)
        try:
            time.sleep(rng.uniform(0.0, 0.15))  # a random moment in the middle of the saves
        finally:
            proc.kill()  # SIGKILL, this process only
            proc.wait(5)
        _complete(path)
    remove_leftovers(path)  # what a boot does first: a crash mid-write left at most an orphan temporary
    assert [p.name for p in tmp_path.iterdir()] == ["vehicle.parm"]


def test_a_reader_during_saves_never_sees_a_partial_file(tmp_path):
    path = tmp_path / "vehicle.parm"
    proc = _hammer(path)
    seen = set()
    try:
        for _ in range(300):
            seen.add(_complete(path)["RTL_MAX_DISP"])
    finally:
        proc.kill()
        proc.wait(5)
    assert seen  # every one of the 300 reads was a whole file


@pytest.mark.parametrize("text, line, what", [
    ("", 1, "empty file"),
    ("# returnlink parameters\nLNK_TIMEOUT      3\nRTL_MAX_DISP     5", 3, "incomplete last line"),
    ("# returnlink parameters\nLNK_TIMEOUT      3\nRTL_MAX_D\n", 3, "expected 'NAME VALUE'"),
    ("LNK_TIMEOUT      3\nRTL_MAX_DISP     -4\n", 2, "outside"),
])
def test_a_damaged_parm_file_is_refused_at_boot_by_name_and_line(tmp_path, capsys, text, line, what):
    path = tmp_path / "vehicle.parm"
    path.write_text(text)
    with pytest.raises(StoredFileError) as e:
        read_parm_file(path)
    assert e.value.line == line and what in e.value.what
    try:  # refused while checking the arguments (SystemExit) or while booting (return code): exit 2 either way
        code = main(["sim", "serve", "tunnel", "--port", "0", "--params", str(path), "--duration", "1"])
    except SystemExit as exit_:
        code = exit_.code
    err = capsys.readouterr().err
    assert code == 2 and f"vehicle.parm:{line}: " in err and what in err
    assert path.read_text() == text  # left as found, for whoever investigates


def test_boot_removes_only_the_orphans_of_its_own_file(tmp_path):
    (tmp_path / ".vehicle.parm.k3j2.tmp").write_text("LNK_TIM")  # a save cut short by a crash
    (tmp_path / ".other.parm.k3j2.tmp").write_text("x")
    (tmp_path / "vehicle.parm").write_text("LNK_TIMEOUT 4\n")
    assert remove_leftovers(tmp_path / "vehicle.parm") == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == [".other.parm.k3j2.tmp", "vehicle.parm"]
