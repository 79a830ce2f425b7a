"""Bad input on the command line never reaches the user as a traceback: each finding of the input review exits 2
with a message naming the file, line, field or argument (``sim.cli.main`` in-process; nothing is simulated)."""

from __future__ import annotations

from pathlib import Path

import pytest

import sim
from sim import runner
from sim.cli import main

TUNNEL = (Path(sim.__file__).parent / "scenarios" / "tunnel.toml").read_text()


def exits_2(args: list[str], capsys) -> str:
    with pytest.raises(SystemExit) as e:
        raise SystemExit(main(args))
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return err


@pytest.mark.parametrize("args, needle", [
    (["gcs", "plan", "upload", "--spec", "rtl:60:0:7"], "RETURN_TO_LINK param3 (target): 7 outside 0..2 or -1"),
    (["gcs", "plan", "show", "--spec", "rtl:60:99"], "param2 (speed): 99 outside 0..5"),
    (["gcs", "plan", "show", "--spec", "rtl:60:0:0:5"], "param4 (on regain)"),
    (["gcs", "plan", "show", "--spec", "rtl:-3"], "param1 (max displacement)"),
    (["gcs", "plan", "show", "--spec", "rtl:nan:0:nan:0.5"], "param4 (on regain): 0.5 must be a whole number"),
    (["sim", "serve", "tunnel", "--port", "99999"], "port must be within 0..65535, got 99999"),
    (["sim", "serve", "tunnel", "--peer", "127.0.0.1:0"], "port must be within 1..65535, got 0"),
    (["sim", "serve", "tunnel", "--duration", "-1"], "seconds must be > 0"),
    (["sim", "serve", "tunnel", "--speedup", "nan"], "speedup must be a finite number"),
    (["sim", "run", "tunnel", "--seed", "-5"], "seed must be within 0..4294967295, got -5"),
    (["sim", "run", "tunnel", "--seed", "five"], "'five' is not a whole number"),
    (["gcs", "--sysid", "300", "status"], "system id must be within 1..255, got 300"),
    (["gcs", "--target", "0", "status"], "system id must be within 1..255, got 0"),
    (["gcs", "--compid", "256", "status"], "component id must be within 1..255, got 256"),
    (["gcs", "--url", "udpin:127.0.0.1:99999", "status"], "port must be within"),
    (["gcs", "--url", "tcp:1.2.3.4:5", "status"], "is not udpin:HOST:PORT or udpout:HOST:PORT"),
    (["gcs", "--timeout", "0", "status"], "seconds must be > 0"),
    (["gcs", "drive", "1", "nan", "3"], "velocity (m/s) must be a finite number"),
    (["gcs", "drive", "1", "0", "-3"], "seconds must be > 0"),
    (["gcs", "claim", "70000"], "lease index must be within -1..65534"),
    (["gcs", "param", "set", "LNK_TIMEOUT", "inf"], "value must be a finite number"),
])
def test_bad_arguments_exit_2_naming_the_argument(args, needle, capsys):
    assert needle in exits_2(args, capsys)


def test_a_return_plan_file_the_vehicle_would_refuse_is_refused_by_file_and_line(tmp_path, capsys):
    plan = tmp_path / "plan.txt"
    plan.write_text("QGC WPL 110\n0\t0\t2\t44002\t60\t0\t7\t-1\t0\t0\t0\t1\n")
    err = exits_2(["gcs", "plan", "upload", str(plan)], capsys)
    assert f"{plan}:2: RETURN_TO_LINK param3 (target)" in err
    plan.write_bytes(b"\xff\xfe\x00garbage")
    assert "codec" in exits_2(["gcs", "plan", "show", str(plan)], capsys)


@pytest.mark.parametrize("edit, needle", [
    (("max_displacement = 60.0", "max_displacment = 60.0"), ":50: operator.plan[0].max_displacment: unknown field; "
                                                             "did you mean 'max_displacement'?"),
    (("position = [-5.0, 0.0]", "position = [nan, 0.0]"), ":41: start.position: must be a finite number"),
    (("seed = 1", "seed = -5"), ":4: seed: must be within 0..4294967295"),
    (("[criteria]", "params = {NOPE = 3}\n[criteria]"), "operator.params.NOPE: no vehicle parameter 'NOPE'"),
    (("points = [[55.9, 19.5], [59.5, 15.9]]", "points = [[55.9, 19.5], [55.9, 19.5]]"), "zero length"),
    (("[0.0, 25.0], [0.0, 2.5]", "[0.0, 25.0], [nan, 2.5]"), ":12: world.walls[0].points: must be a finite"),
])
def test_broken_scenario_files_exit_2_by_file_line_and_field(tmp_path, capsys, edit, needle):
    assert edit[0] in TUNNEL
    bad = tmp_path / "bad.toml"
    bad.write_text(TUNNEL.replace(*edit, 1))
    err = exits_2(["sim", "run", str(bad), "--quiet"], capsys)
    assert f"{bad}{needle}" in err or (needle[0] != ":" and needle in err and str(bad) in err), err


def test_a_binary_scenario_file_is_an_error_not_a_traceback(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_bytes(b"\xff\xfe\x00\x01")
    assert "codec" in exits_2(["sim", "run", str(bad)], capsys)


def test_an_unwritable_output_directory_fails_before_simulating(monkeypatch, capsys):
    monkeypatch.setattr(runner.Run, "run", lambda self: pytest.fail("simulated before checking --out"))
    err = exits_2(["sim", "run", "open", "--out", "/proc/x", "--quiet"], capsys)
    assert "cannot write to output directory /proc/x" in err
    err = exits_2(["sim", "serve", "open", "--out", "/proc/x", "--port", "0"], capsys)
    assert "cannot write to output directory /proc/x" in err


def test_a_write_error_after_the_run_is_a_message_not_a_traceback(tmp_path, monkeypatch, capsys):
    short = tmp_path / "short.toml"
    short.write_text(TUNNEL.replace("duration = 200.0", "duration = 2.0"))

    def full_disk(*args):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(runner, "write_tlog", full_disk)
    err = exits_2(["sim", "run", str(short), "--out", str(tmp_path / "out"), "--quiet"], capsys)
    assert "cannot write the results to" in err and "No space left on device" in err


def test_bad_parm_files_exit_2_by_file_and_line(tmp_path, capsys):
    parm = tmp_path / "bad.parm"
    parm.write_text("LNK_TIMEOUT 3\nRTL_SPEED 99\n")
    err = exits_2(["sim", "serve", "tunnel", "--params", str(parm)], capsys)
    assert f"{parm}:2: RTL_SPEED: 99 outside 0..5" in err
    parm.write_text("LNK_TIMEOUT 3\nNOPE 1\n")
    err = exits_2(["gcs", "--url", "udpin:127.0.0.1:1", "--timeout", "0.2", "param", "load", str(parm)], capsys)
    assert f"{parm}:2: NOPE: unknown parameter" in err


def test_a_served_companions_bad_files_exit_2_before_the_firmware_boots(tmp_path, monkeypatch, capsys):
    # --params, --key and --state configure the companion under `sim serve --vehicle ardurover --policy companion`,
    # checked as the native vehicle's are, before any firmware process is started
    from sim.serve import Server

    monkeypatch.setattr(Server, "serve", lambda self, *a, **k: pytest.fail("served a bad set-up"))
    fake = tmp_path / "ardurover"
    fake.write_text("#!/bin/sh\nexit 1\n")
    fake.chmod(0o755)
    base = ["sim", "serve", "tunnel", "--vehicle", "ardurover", "--policy", "companion", "--firmware", str(fake),
            "--out", str(tmp_path / "out"), "--port", "0"]
    parm = tmp_path / "bad.parm"
    parm.write_text("LNK_TIMEOUT 3\nRTL_SPEED 99\n")
    assert f"{parm}:2: RTL_SPEED: 99 outside 0..5" in exits_2([*base, "--params", str(parm)], capsys)
    assert "key file" in exits_2([*base, "--key", str(tmp_path / "missing.key")], capsys)
    blocked = tmp_path / "file"
    blocked.write_text("")
    assert "cannot create the state directory" in exits_2([*base, "--state", str(blocked / "sub")], capsys)
    # the firmware's own failsafes keep refusing what would configure returnlink
    err = exits_2(["sim", "serve", "tunnel", "--vehicle", "ardurover", "--firmware", str(fake), "--params",
                   str(parm)], capsys)
    assert "--params configures returnlink's own vehicle" in err
