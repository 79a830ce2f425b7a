"""The real ArduPilot Rover firmware in the tunnel (docs/architecture.md §10): its own failsafes, its mode
timeline, paired across policies until the loss, repeatable until the loss, two runs side by side, the bridge's
frame rules mid-run, and stopped on SIGTERM."""

from __future__ import annotations

import json
import math
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from sim import metrics
from sim.campaign import sweep
from sim.campaign.executors import SerialExecutor
from sim.campaign.spec import parse_spec
from sim.cli import main
from sim.compare import differing as differing_within
from sim.firmware.bridge import MAGIC, SERVO_PACKET, FrameVerdict
from sim.firmware.metrics import REPEATABILITY, TOLERANCE
from sim.firmware.process import FirmwareError, wait_for
from sim.firmware_runs import FirmwareRun
from sim.scenario import load
from tests.firmware_helpers import firmware_or_skip, short_scenario

pytestmark = pytest.mark.firmware

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def firmware() -> Path:
    return firmware_or_skip()


@pytest.fixture(scope="module")
def runs(firmware):
    """The tunnel cut to 100 s, flown by each firmware policy (one firmware process each, one after another)."""
    sc = load("tunnel")
    out = {}
    for policy in ("ardupilot-smartrtl", "ardupilot-hold", "ardupilot-rtl"):
        run = FirmwareRun(sc, 1, policy, firmware, duration=100.0).run()
        run.metrics = metrics.compute(run)
        out[policy] = run
    return out


def modes(run) -> list[str]:
    return [e["mode"] for e in run.metrics["firmware_modes"]]


def test_smartrtl_turns_back_by_itself_after_the_link_dies(runs):
    m = runs["ardupilot-smartrtl"].metrics
    assert modes(runs["ardupilot-smartrtl"])[:3] == ["MANUAL", "GUIDED", "SMART_RTL"]
    assert m["firmware"].startswith("ArduRover V")
    assert m["loss_position"][0] > 30  # the link died deep in the adit
    # FS_GCS_TIMEOUT = LNK_TIMEOUT after the last GCS heartbeat, then FS_TIMEOUT (1.5 s) before the action:
    # ArduPilot's documented rule. The loss is timed from the last frame the firmware heard, and the operator
    # streams its stick at 10 Hz between its 1 Hz heartbeats (sim/firmware/operator.py), so it can fall up to 1 s
    # after the last heartbeat the failsafe counts
    assert 0.4 <= m["reaction_latency_s"] <= 2.5
    assert m["distance_back_m"] > 30 and m["rest_position"][0] < 5  # it retraced the drift towards home
    assert m["regained_by"] == "return" and m["link_regained_s"] > m["return_started_s"]
    assert m["lease_events"] == [] and m["stale_commands_executed"] is None  # no leases in the firmware: said


def test_hold_stops_where_it_lost_the_link_and_never_regains_it(runs):
    m = runs["ardupilot-hold"].metrics
    assert modes(runs["ardupilot-hold"])[:3] == ["MANUAL", "GUIDED", "HOLD"]
    assert m["distance_back_m"] < 1.0
    assert m["link_regained_s"] is None and m["final_target_error_m"] is None
    assert not m["passed"] and "link never regained after the loss" in m["failures"]


def test_rtl_heads_straight_for_home(runs):
    run = runs["ardupilot-rtl"]
    assert "RTL" in modes(run)
    m = run.metrics
    start = next(r for r in run.rows if r[0] >= m["return_started_s"])
    home = (-5.0, 0.0)
    assert m["distance_back_m"] > 3
    assert min(((r[1] - home[0]) ** 2 + (r[2] - home[1]) ** 2) ** 0.5 for r in run.rows if r[0] > start[0]) < \
        ((start[1] - home[0]) ** 2 + (start[2] - home[1]) ** 2) ** 0.5 - 3


def _on_path(p: list[float], rows: list[tuple], until: float) -> float:
    """How far the point ``p`` lies from a run's true path before ``until``."""
    return min(math.dist(p, r[1:3]) for r in rows if r[0] < until)


def _same_drive(a, b) -> None:
    """Two runs of one trial drove the same way until the earlier one's failsafe acted, and lost the link on that
    way: the firmware's own threads (sim/firmware/metrics.py) may move a frame by a tick, a tenth of a metre at the
    fringe, and where the fringe is a knife edge that tenth can move the last packet heard by most of a second
    (tunnel, seed 1: 46.06 s or 45.28 s, 0.59 m apart, one run in three); so the moment of the loss is compared as
    a place on the common path, and the failsafe's reaction to it as a time."""
    t_act = min(a.metrics["return_started_s"], b.metrics["return_started_s"])
    pairs = [(r, q) for r, q in zip(a.rows, b.rows, strict=False) if r[0] < t_act]
    assert len(pairs) > 1000
    assert max(math.dist(r[1:3], q[1:3]) for r, q in pairs) < 0.25
    assert _on_path(a.metrics["loss_position"], b.rows, t_act) < 0.25
    assert _on_path(b.metrics["loss_position"], a.rows, t_act) < 0.25


def _reaction(m: dict) -> float:
    return m["return_started_s"] - m["link_lost_s"]


def test_policies_fly_the_same_trace_until_the_failsafe(runs):
    """Same world, seeds, radio fates and operator: the firmware's failsafe setting is the only difference, and it
    only acts after the loss, so the true paths agree until then (``_same_drive``) and each failsafe answers the
    loss after the same time."""
    a, b = runs["ardupilot-smartrtl"], runs["ardupilot-hold"]
    _same_drive(a, b)
    assert abs(_reaction(a.metrics) - _reaction(b.metrics)) <= 2 * TOLERANCE["s"]


def test_same_seed_flies_the_same_drive_until_the_loss(runs, firmware):
    """Repeatable within the firmware's own determinism: the drive until the loss and the failsafe's reaction to it
    agree (``_same_drive``, TOLERANCE); what follows may not (sim/firmware/metrics.py says why)."""
    again = FirmwareRun(load("tunnel"), 1, "ardupilot-smartrtl", firmware, duration=100.0).run()
    again.metrics = metrics.compute(again)
    first = runs["ardupilot-smartrtl"]
    _same_drive(first, again)
    assert abs(_reaction(first.metrics) - _reaction(again.metrics)) <= 2 * TOLERANCE["s"]
    assert [e["mode"] for e in again.metrics["firmware_modes"]][:3] == ["MANUAL", "GUIDED", "SMART_RTL"]


def differing(a: dict, b: dict) -> list[str]:
    """The comparator as a replay of a firmware trial asks it."""
    return differing_within(a, b, REPEATABILITY)


def test_differing_sees_a_real_difference_and_forgives_jitter(runs):
    m = runs["ardupilot-smartrtl"].metrics
    jitter = {**m, "return_started_s": m["return_started_s"] + 0.06, "collisions": m["collisions"] + 1}
    assert differing(m, jitter) == []
    moved = {**m, "rest_position": [m["rest_position"][0] + 5, m["rest_position"][1]],
             "firmware_modes": m["firmware_modes"][:-1]}
    assert differing(m, moved) == ["firmware_modes", "rest_position"]
    # a mode change a second late is the operator's retry; two seconds late, or another mode, is a difference
    modes = m["firmware_modes"]
    late = [{**x, "t": x["t"] + 1.0} if i == 1 else x for i, x in enumerate(modes)]
    later = [{**x, "t": x["t"] + 2.0} if i == 1 else x for i, x in enumerate(modes)]
    other = [{**x, "mode": "HOLD"} if i == 1 else x for i, x in enumerate(modes)]
    assert differing(m, {**m, "firmware_modes": late}) == []
    assert differing(m, {**m, "firmware_modes": later}) == differing(m, {**m, "firmware_modes": other}) == \
        ["firmware_modes"]


def test_two_runs_side_by_side_claim_different_instances(firmware):
    sc = load("tunnel")
    got: dict[int, FirmwareRun] = {}
    errors: list[BaseException] = []

    def fly(seed: int) -> None:
        try:
            got[seed] = FirmwareRun(sc, seed, "ardupilot-hold", firmware, duration=30.0).run()
        except BaseException as e:  # noqa: BLE001 - reported below
            errors.append(e)

    threads = [threading.Thread(target=fly, args=(s,)) for s in (1, 2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(120)
    assert not errors
    assert got[1].link.process.instance != got[2].link.process.instance
    assert all(len(r.rows) == 1500 for r in got.values())
    assert not any(r.link.process.alive() for r in got.values())


def _children(pid: int) -> list[int]:
    try:
        text = Path(f"/proc/{pid}/task/{pid}/children").read_text()
    except OSError:
        return []
    return [int(c) for c in text.split()]


def test_sigterm_to_sim_run_stops_its_firmware(firmware, tmp_path):
    env = {**os.environ, "RETURNLINK_ARDUROVER": str(firmware)}
    p = subprocess.Popen([sys.executable, "-m", "sim.cli", "sim", "run", "tunnel", "--vehicle", "ardurover",
                          "--out", str(tmp_path / "o"), "--quiet"], cwd=ROOT, env=env,
                         stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 30
        kids: list[int] = []
        while time.monotonic() < deadline and not kids:
            kids = [k for k in _children(p.pid) if "ardurover" in Path(f"/proc/{k}/cmdline").read_text()]
            time.sleep(0.1)
        assert kids, "the firmware never started"
        time.sleep(1.0)
        p.send_signal(signal.SIGTERM)
        err = p.communicate(timeout=20)[1]
        assert p.returncode == 130 and "the firmware was stopped" in err
        assert all(wait_for(k, 5.0) for k in kids)
    finally:
        if p.poll() is None:
            p.kill()


def test_sim_run_writes_its_outputs_and_a_sweep_puts_firmware_rows_beside_native(firmware, tmp_path, capsys):
    scenario = short_scenario(tmp_path, duration=80.0)
    rc = main(["sim", "run", str(scenario), "--vehicle", "ardurover", "--firmware", str(firmware),
               "--out", str(tmp_path / "run"), "--quiet"])
    out = capsys.readouterr().out
    assert rc in (0, 1) and "firmware modes:" in out and "SMART_RTL" in out
    for f in ("metrics.json", "run.tlog", "trajectory.png", "timeline.png", "firmware.log"):
        assert (tmp_path / "run" / f).stat().st_size > 0, f
    m = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert m["vehicle"] == "ardurover" and m["policy"] == "ardupilot-smartrtl"

    spec = parse_spec(f'scenarios = ["{scenario}"]\nvehicles = ["rover", "ardurover"]\n'
                      'policies = ["returnlink", "ardupilot-hold"]\nseeds = [1]\n', str(tmp_path / "s.toml"))
    assert sorted((t.vehicle, t.policy) for t in spec.trials) == [("ardurover", "ardupilot-hold"),
                                                                   ("rover", "returnlink")]
    store = sweep.Store(tmp_path / "sweep")
    with SerialExecutor() as ex:
        sweep.run_sweep(spec, store, ex, progress=False)
    rows = {r["policy"]: r for r in store.rows.values()}
    assert rows["ardupilot-hold"]["status"] in ("ok", "failed") and rows["ardupilot-hold"]["error"] is None
    fw_modes = rows["ardupilot-hold"]["firmware_modes"]
    assert (json.loads(fw_modes) if isinstance(fw_modes, str) else fw_modes)[-1]["mode"] == "HOLD"
    assert rows["returnlink"].get("firmware") is None
    summary = (tmp_path / "sweep" / "summary.csv").read_text()
    assert "ardupilot-hold" in summary and "returnlink" in summary
    fw = next(t for t in spec.trials if t.vehicle == "ardurover")
    rc = main(["sim", "run", "--replay", str(tmp_path / "sweep"), fw.id, "--out", str(tmp_path / "r"), "--quiet",
               "--no-plots"])
    out, err = capsys.readouterr()
    assert rc in (0, 1)
    assert "metrics match the stored trial within" in out or "did not repeat the stored trial exactly" in err


class Injecting(FirmwareRun):
    """A run into whose bridge socket a stranger sends ``packet`` once, 1 s into the scenario."""

    packet = b""

    def _tick(self, t: float) -> None:
        if abs(t - 1.0) < 1e-6:
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            s.sendto(self.packet, self.link.json_sock.getsockname())
            s.close()
        super()._tick(t)


def test_a_malformed_packet_on_the_bridge_is_counted_and_ignored(firmware):
    run = type("Garbage", (Injecting,), {"packet": b"\x00garbage, not a servo packet"})(
        load("tunnel"), 1, "ardupilot-hold", firmware, duration=5.0).run()
    assert run.link.rules.counts[FrameVerdict.MALFORMED] == 1
    assert len(run.rows) == 250 and not run.link.process.alive()


def test_a_frame_counter_that_goes_back_ends_the_run_and_its_firmware(firmware):
    run = type("Restart", (Injecting,), {"packet": SERVO_PACKET.pack(MAGIC, 200, 0, *([1500] * 16))})(
        load("tunnel"), 1, "ardupilot-hold", firmware, duration=5.0)
    with pytest.raises(FirmwareError, match="restarted"):
        run.run()
    assert not run.link.process.alive()


def test_a_repeated_frame_is_answered_again_without_a_physics_step(firmware):
    stranger = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    stranger.settimeout(5.0)

    class Repeat(FirmwareRun):
        def _boot(self) -> None:
            super()._boot()
            self.steps_at_boot = self.link.rules.counts[FrameVerdict.STEP]

        def _tick(self, t: float) -> None:
            if abs(t - 1.0) < 1e-6:  # the frame just stepped, sent again: the bridge answers on its next read
                frame = SERVO_PACKET.pack(MAGIC, 200, self.link.rules.last, *([1500] * 16))
                stranger.sendto(frame, self.link.json_sock.getsockname())
            super()._tick(t)

    try:
        run = Repeat(load("tunnel"), 1, "ardupilot-hold", firmware, duration=3.0).run()
        answer = stranger.recv(4096)
    finally:
        stranger.close()
    counts = run.link.rules.counts
    assert counts[FrameVerdict.REPEAT] >= 1 and answer.startswith(b"\n{") and b'"timestamp":' in answer
    # a physics step per new frame, none per repeat (200 Hz: 5 ms each)
    assert run.link.t_fw - run.link.boot_s == pytest.approx((counts[FrameVerdict.STEP] - run.steps_at_boot) * 0.005)
