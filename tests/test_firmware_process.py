"""Finding the firmware and owning its process, without the firmware: a stand-in program that ignores SIGTERM
shows the SIGKILL fallback, and a killed parent shows the kernel's parent-death signal."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from sim.firmware import process
from sim.firmware.locate import ENV, FirmwareNotFound, find_firmware
from sim.firmware.process import FirmwareProcess, claim_instance, wait_for

pytestmark = pytest.mark.firmware


def executable(path, body="#!/bin/sh\nexit 0\n"):
    path.write_text(body)
    path.chmod(0o755)
    return path


def test_the_option_wins_then_the_environment_then_path(tmp_path):
    a, b, c = (executable(tmp_path / n) for n in ("a", "b", "ardurover"))
    env = {ENV: str(b), "PATH": str(tmp_path)}
    assert find_firmware(str(a), env) == a.resolve()
    assert find_firmware(None, env) == b.resolve()
    assert find_firmware(None, {"PATH": str(tmp_path)}) == c.resolve()


def test_missing_firmware_names_the_three_ways_and_how_to_build_one(tmp_path):
    with pytest.raises(FirmwareNotFound) as e:
        find_firmware(None, {"PATH": str(tmp_path)})
    text = str(e.value)
    assert "--firmware" in text and ENV in text and "ardurover" in text and "./waf rover" in text


def test_a_given_way_that_is_unusable_is_an_error_not_a_fallback(tmp_path):
    executable(tmp_path / "ardurover")
    (tmp_path / "not-exec").write_text("")
    with pytest.raises(FirmwareNotFound, match="--firmware"):
        find_firmware(str(tmp_path / "not-exec"), {"PATH": str(tmp_path)})
    with pytest.raises(FirmwareNotFound, match=ENV):
        find_firmware(None, {ENV: str(tmp_path / "nope"), "PATH": str(tmp_path)})


@pytest.mark.parametrize("pid", [0, 199, 200, 398])
def test_a_search_from_the_process_id_never_takes_instance_0(monkeypatch, pid):
    """Instance 0 (TCP 5760) is a person's own SITL's, and the README walkthrough's: a simulator run beside it, or a
    test beside the walkthrough, must not take its ports. Processes whose id once led the search to 0 start at 1."""
    monkeypatch.delenv(process.INSTANCE_ENV, raising=False)
    monkeypatch.setattr(process.os, "getpid", lambda: pid)
    n, sock = claim_instance()
    sock.close()
    assert 1 <= n <= process.MAX_INSTANCE


def test_an_instance_is_claimed_by_its_bound_port_and_never_twice():
    n1, s1 = claim_instance(start=150)
    n2, s2 = claim_instance(start=150)
    try:
        assert n1 != n2
        assert s1.getsockname()[1] == process.JSON_PORT + 10 * n1
    finally:
        s1.close()
        s2.close()


STUBBORN = textwrap.dedent("""\
    import signal, sys, time
    signal.signal(signal.SIGTERM, signal.SIG_IGN)  # as the firmware does once its physics is gone
    print("ready", flush=True)
    time.sleep(60)
""")


def test_stop_kills_a_process_that_ignores_sigterm(tmp_path):
    fw = FirmwareProcess(sys.executable, 0, ["-c", STUBBORN], workdir=tmp_path / "w").start()
    pid = fw.pid
    deadline = time.monotonic() + 10
    while "ready" not in fw.log_path.read_text() and time.monotonic() < deadline:
        time.sleep(0.02)
    status = fw.stop(keep_log=tmp_path / "kept.log")
    assert status == -signal.SIGKILL  # SIGTERM alone would have left it running
    assert wait_for(pid, 2.0)
    assert (tmp_path / "kept.log").read_text().startswith("ready")
    assert fw.stop() == status  # idempotent


def test_the_child_dies_with_a_parent_killed_without_clean_up(tmp_path):
    """A worker killed by SIGKILL runs no ``finally``: the kernel's parent-death signal still ends its firmware."""
    parent = textwrap.dedent(f"""\
        import sys, time
        from pathlib import Path
        from sim.firmware.process import FirmwareProcess
        fw = FirmwareProcess(sys.executable, 0, ["-c", {STUBBORN!r}], workdir=Path({str(tmp_path / 'p')!r})).start()
        print(fw.pid, flush=True)
        time.sleep(60)
    """)
    p = subprocess.Popen([sys.executable, "-c", parent], stdout=subprocess.PIPE, text=True,
                         cwd=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    try:
        child = int(p.stdout.readline())
        os.kill(child, 0)  # running
        p.kill()
        p.wait()
        assert wait_for(child, 5.0), "the child outlived its parent"
    finally:
        if p.poll() is None:
            p.kill()


def test_sim_run_without_any_firmware_exits_2_naming_the_three_ways(tmp_path, monkeypatch, capsys):
    from sim.cli import main

    monkeypatch.delenv(ENV, raising=False)
    monkeypatch.setenv("PATH", str(tmp_path))
    with pytest.raises(SystemExit) as e:
        main(["sim", "run", "tunnel", "--vehicle", "ardurover", "--out", str(tmp_path / "o")])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert "--firmware PATH" in err and ENV in err and "Traceback" not in err


@pytest.mark.parametrize("args, words", [
    (["--vehicle", "ardurover", "--policy", "smartrtl"], "firmware's own failsafes"),
    (["--policy", "ardupilot-hold"], "use --vehicle ardurover"),
])
def test_a_policy_the_vehicle_cannot_fly_exits_2(args, words, tmp_path, capsys):
    from sim.cli import main

    with pytest.raises(SystemExit) as e:
        main(["sim", "run", "tunnel", "--out", str(tmp_path / "o"), *args])
    assert e.value.code == 2 and words in capsys.readouterr().err


@pytest.mark.parametrize("body, field", [
    ('scenarios = ["tunnel"]\npolicies = ["ardupilot-smartrtl"]\n', "policies[0]"),
    ('scenarios = ["tunnel"]\nvehicles = ["ardurover"]\npolicies = ["returnlink"]\n', "policies[0]"),
    ('scenarios = ["tunnel"]\nvehicles = ["rover", "ardurover"]\npolicies = ["hold"]\n', "vehicles[1]"),
])
def test_a_spec_pairing_no_vehicle_with_a_policy_is_an_error_naming_the_field(body, field):
    from sim.campaign.spec import SpecError, parse_spec

    with pytest.raises(SpecError) as e:
        parse_spec(body, "s.toml")
    assert e.value.field == field and e.value.line is not None
