"""The command line as a user runs it: files written, errors named, exit codes."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from sim.cli import main
from sim.metrics import KEYS
from tests.interop import ServedVehicle

pytestmark = pytest.mark.interop


def returnlink(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "sim.cli", *args], capture_output=True, text=True,
                          timeout=timeout)


def test_sim_run_writes_metrics_tlog_and_plots(tmp_path):
    out = tmp_path / "run"
    r = returnlink("sim", "run", "open", "--vehicle", "legged", "--seed", "11", "--out", str(out), "--quiet")
    assert r.returncode in (0, 1), r.stderr
    m = json.loads((out / "metrics.json").read_text())
    assert tuple(m) == KEYS and m["vehicle"] == "legged" and m["seed"] == 11
    assert (r.returncode == 0) == m["passed"]
    for name in ("trajectory.png", "timeline.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    from pymavlink import mavutil

    log = mavutil.mavlink_connection(str(out / "run.tlog"), dialect="returnlink")
    kinds = set()
    while (msg := log.recv_match()) is not None:
        kinds.add(msg.get_type())
    assert {"HEARTBEAT", "LEASE_STATUS", "COMMAND_ACK", "RADIO_STATUS", "SET_POSITION_TARGET_LOCAL_NED"} <= kinds
    assert "PASSED" in r.stdout or "FAILED" in r.stdout


@pytest.mark.parametrize("args, needle", [
    (["sim", "run", "nowhere"], "no such scenario"),
    (["sim", "run", "tunnel", "--vehicle", "hovercraft"], "invalid choice"),
    (["sim", "serve", "tunnel", "--speedup", "0"], "--speedup: speedup must be > 0"),
    (["gcs", "plan", "show", "--spec", "fly:3"], "expected rtl"),
    (["gcs", "plan", "upload", "/no/such/plan.txt"], "No such file"),
])
def test_bad_input_exits_2_naming_the_problem(args, needle, capsys):
    with pytest.raises(SystemExit) as e:
        code = main(args)
        raise SystemExit(code)
    assert e.value.code == 2
    assert needle in capsys.readouterr().err


def test_broken_scenario_file_names_file_line_and_field(tmp_path, capsys):
    import sim

    text = (Path(sim.__file__).parent / "scenarios" / "tunnel.toml").read_text()
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace("duration = 200.0", "duration = -5"))
    with pytest.raises(SystemExit) as e:
        main(["sim", "run", str(bad)])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert "bad.toml:3: duration" in err


def test_gcs_commands_against_a_served_vehicle(tmp_path, capsys):
    served = ServedVehicle("tunnel")
    url = ["gcs", "--url", f"udpin:127.0.0.1:{served.gcs_port}"]
    try:
        assert main([*url, "acquire"]) == 0
        assert "in control: epoch" in capsys.readouterr().out
        # one-shot commands leave the owner silent between them (`gcs shell` keeps the link): give the gaps room
        assert main([*url, "param", "set", "LNK_TIMEOUT", "30"]) == 0
        assert main([*url, "plan", "upload", "--spec", "rtl:40 | loiter:10 | launch"]) == 0
        plan = tmp_path / "plan.txt"
        assert main([*url, "plan", "download", str(plan)]) == 0
        assert plan.read_text().startswith("QGC WPL 110") and len(plan.read_text().splitlines()) == 6
        assert main([*url, "param", "set", "LNK_TIMEOUT", "999"]) == 1
        assert "refused" in capsys.readouterr().err
        parm = tmp_path / "saved.parm"
        assert main([*url, "param", "save", str(parm)]) == 0
        assert "LNK_TIMEOUT" in parm.read_text()
        assert main([*url, "status"]) == 0
        assert "state TELEOP" in capsys.readouterr().out
        assert len(served.vehicle.book.plan) == 3
    finally:
        served.close()
    assert main(["gcs", "--url", "udpin:127.0.0.1:1", "--timeout", "0.5", "status"]) == 1
