"""Campaigns on Ray, end to end on loopback: a local Ray started inside `returnlink sim sweep`, a worker that dies
and a trial that hangs under Ray, and a sweep joining a cluster started with `ray start --head`."""

from __future__ import annotations

import contextlib
import csv
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from sim.campaign import executors
from sim.campaign.executors import RayExecutor
from sim.campaign.trial import Trial
from sim.cli import main
from tests.campaign_helpers import dies_once, ignores_alarm, jam_scenario, pid_row, sleeps, write_spec
from tests.interop import free_udp_port

pytestmark = pytest.mark.interop

RAY = Path(sys.executable).with_name("ray")


def small_campaign(tmp: Path) -> Path:
    jam_scenario(tmp)
    return write_spec(tmp, 'scenarios = ["jam.toml"]\nseeds = {from = 1, to = 2}\ntimeout_s = 120\n')


def test_sweep_starts_a_local_ray_and_writes_rows_summary_and_report(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["sim", "sweep", str(small_campaign(tmp_path)), "--out", str(out), "--workers", "2"]) == 0
    rows = pq.read_table(out / "trials.parquet").to_pylist()
    assert sorted(r["seed"] for r in rows) == [1, 2]
    assert all(r["status"] in ("ok", "failed") and r["link_lost_s"] is not None for r in rows)
    (line,) = csv.DictReader((out / "summary.csv").open())
    assert (line["scenario"], line["n"], line["errors"]) == ("jam", "2", "0")
    assert "returnlink sim run --replay" in (out / "report.md").read_text()
    captured = capsys.readouterr()
    assert "2 to run on a local Ray" in captured.err and "2/2 trials" in captured.err
    assert "| jam | rover | returnlink | - | 2 | 0 |" in captured.out  # "-": no parameter swept


@pytest.fixture(scope="module")
def head():
    """`ray start --head` on loopback with one CPU, as a user would start a cluster; its address."""
    port = free_udp_port()  # GCS is TCP; a port free for UDP on loopback is almost surely free for TCP too
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parent.parent), "RAY_USAGE_STATS_ENABLED": "0"}
    env.pop("RAY_ADDRESS", None)
    # its own temp dir, so the cluster address it records is not left behind for other Ray users of the machine
    temp = tempfile.mkdtemp(prefix="rlray")
    proc = subprocess.Popen(
        [str(RAY), "start", "--head", "--port", str(port), "--node-ip-address", "127.0.0.1", "--num-cpus", "1",
         "--include-dashboard", "false", "--disable-usage-stats", "--temp-dir", temp, "--block"],
        env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        _wait_for_port(port, 60)
        yield proc, f"127.0.0.1:{port}"
    finally:
        _stop_group(proc)
        shutil.rmtree(temp, ignore_errors=True)


def _wait_for_port(port: int, timeout: float) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.2)
    raise AssertionError(f"ray head did not listen on {port} within {timeout} s")


def test_sweep_joins_a_cluster_started_with_ray_start(tmp_path, head):
    proc, address = head
    out = tmp_path / "out"
    # a fresh process, as a user runs it: nothing Ray set up in this one (token mode) may help it connect
    env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_")}
    env["PYTHONPATH"] = str(Path(__file__).resolve().parent.parent)
    r = subprocess.run([sys.executable, "-m", "sim.cli", "sim", "sweep", str(small_campaign(tmp_path)), "--out",
                        str(out), "--address", address, "--quiet"], env=env, capture_output=True, text=True,
                       timeout=240)
    assert r.returncode == 0, r.stderr[-3000:]
    assert f"to run on Ray at {address} (1 CPUs)" in r.stderr
    rows = pq.read_table(out / "trials.parquet").to_pylist()
    assert sorted(r["seed"] for r in rows) == [1, 2] and all(r["status"] != "error" for r in rows)
    assert proc.poll() is None  # joining leaves the cluster running


def test_ray_retries_a_dead_worker_once_and_ends_trials_past_their_timeout(tmp_path, monkeypatch, head):
    crash = [Trial("x", str(tmp_path / "x.toml"), "name = 'x'\n", "rover", s) for s in (1, 2)]
    slow, hang, after = (Trial("y", str(tmp_path / "y.toml"), "name = 'y'\n", "rover", s) for s in (3, 4, 5))
    with RayExecutor(address=head[1]) as ex:
        rows = list(ex.map(crash, 60.0, dies_once))
        (before,) = ex.map([after], 60.0, pid_row)
        monkeypatch.setattr(executors, "HARD_KILL_GRACE_S", 120.0)
        (alarmed,) = ex.map([slow], 1.0, sleeps)
        (kept,) = ex.map([after], 60.0, pid_row)
        monkeypatch.setattr(executors, "HARD_KILL_GRACE_S", 1.0)
        (stuck,) = ex.map([hang], 1.0, ignores_alarm)
    assert sorted(r["seed"] for r in rows) == [1, 2]
    assert all(r["status"] == "ok" for r in rows)  # each worker died once; the retry finished the trial
    assert (tmp_path / "x.died-1").is_file() and (tmp_path / "x.died-2").is_file()
    # the alarm ends a slow trial inside its worker, which lives on for the next trial
    assert alarmed["status"] == "error" and alarmed["error"] == "timed out after 1 s (wall clock)"
    assert kept["error"] == before["error"]
    # a trial deaf to the alarm is killed from the driver
    assert stuck["status"] == "error" and stuck["error"] == "timed out after 1 s (wall clock)"


def _stop_group(proc: subprocess.Popen) -> None:
    """Stop the head we started, by its own process id: SIGTERM to `ray start --block` drains the node and stops
    the processes it started; whatever is left of its process group is then killed. Never `ray stop`: that
    kills every Ray of the user."""
    if proc.poll() is None:
        proc.terminate()
        with contextlib.suppress(subprocess.TimeoutExpired):
            proc.wait(30)
    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, signal.SIGKILL)
    proc.wait(10)


@pytest.fixture(autouse=True)
def _no_ray_address(monkeypatch):
    # a RAY_ADDRESS in the environment would make the "local" sweep join someone else's cluster
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
