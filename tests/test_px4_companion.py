"""returnlink companion beside PX4 (docs/architecture.md §11.2): the autopilot recognised from its HEARTBEAT, the
return driven in Offboard (a velocity stream first, then the switch), a brake and Hold on LINK_REGAINED, the
dead-man's Hold, PX4's parameters read and written bytewise for ``--check`` / ``--configure``; and against the real
PX4 rover: policy ``companion`` on vehicle ``px4rover`` in the tunnel (lost, returned in Offboard, regained by the
return, no contact), a companion killed mid-return leaving the rover in PX4's own Hold within COM_OF_LOSS_T + 2 s,
and PX4's own parameter encoding.

The fast tests run against ``tests.px4_standin.FakePX4``. The real PX4 comes from $RETURNLINK_PX4, else the shared
tree beside the repository (as in test_px4_plant.py): with neither those tests skip, and a variable that is set but
unusable fails them."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import ardupilotmega as apm

from sim import metrics
from sim.cli import main
from sim.plants.px4_companion import PX4CompanionPlant, configured, px4_companion_params
from sim.policies import flies
from sim.px4.lockstep import HOLD, OFFBOARD, nav_state_name
from sim.runner import Run, plant_for
from sim.scenario import parse
from tests.companion_rig import FakeAutopilot, Rig
from tests.firmware_helpers import px4_or_skip
from tests.px4_standin import INT32, PX4_DEFAULTS, REAL32, FakePX4
from tests.test_companion_cli import FakeAutopilotServer
from tests.test_px4_plant import ROOT, Started
from vehicle.companion import px4
from vehicle.companion.rules import ArduPilotRules, PX4Rules
from vehicle.companion.setup import PX4_NEEDS, check, differing, needs_for
from vehicle.lease import ExpireReason
from vehicle.params import Params

pytestmark = [pytest.mark.interop, pytest.mark.firmware]


# ----- which autopilot --------------------------------------------------------------------------------------------
def test_the_heartbeat_says_which_autopilot_and_each_gets_its_own_rules():
    for ap, rules in ((FakePX4(), PX4Rules), (FakeAutopilot(), ArduPilotRules)):
        rig = Rig(autopilot=ap)
        assert rig.run(3, lambda r=rig: r.companion.vehicle is not None)
        assert rig.companion.driver.rules is rules and rig.companion.identity_problem is None
    assert needs_for(apm.MAV_AUTOPILOT_PX4) == PX4_NEEDS and needs_for(apm.MAV_AUTOPILOT_ARDUPILOTMEGA) != PX4_NEEDS


@pytest.mark.parametrize("ap, says", [
    (FakePX4(mav_type=apm.MAV_TYPE_QUADROTOR), "PX4 for a QUADROTOR, not a PX4 rover"),
    (FakeAutopilot(autopilot=apm.MAV_AUTOPILOT_GENERIC), "GENERIC, not ArduPilot or PX4"),
])
def test_an_autopilot_it_cannot_drive_is_named_and_never_booted_on(ap, says):
    rig = Rig(autopilot=ap)
    rig.run(3)
    assert says in (rig.companion.identity_problem or "") and rig.companion.vehicle is None


# ----- the return in Offboard (stand-in) --------------------------------------------------------------------------
def configure(ap: FakePX4) -> None:
    """The stand-in's parameters as ``returnlink companion --configure`` leaves them."""
    values = configured({name: v for name, (v, _) in ap.typed.items()})
    ap.typed = {name: (values[name], ptype) for name, (_, ptype) in ap.typed.items()}


def owned_px4(**kw):
    """A booted companion beside the PX4 stand-in (configured), owned by GCS 255, armed, moved 20 m out."""
    ap = FakePX4()
    configure(ap)
    rig = Rig(autopilot=ap, **kw)
    assert rig.run(5, lambda: rig.companion.vehicle is not None)
    gs = rig.station()
    p = gs.acquire()
    assert rig.run(2, lambda: p.done) and p.result == 0
    rig.send_as(gs, lambda m: m.command_long_encode(1, 1, apm.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0))
    assert rig.run(1, lambda: rig.ap.armed)
    rig.ap.x = 20.0
    rig.run(1)
    return rig, gs


def owner_streaming(rig: Rig, owner, seconds: float, vx: float = 1.0, switch: bool = True) -> None:
    """The owner's Offboard drive: BODY_NED velocity at 10 Hz (and, ``switch``, Offboard asked for once it runs)."""
    for k in range(int(round(seconds / 0.1))):
        rig.send_as(owner, lambda m: m.set_position_target_local_ned_encode(
            0, 1, 1, apm.MAV_FRAME_BODY_NED, 0x0DC7, 0, 0, 0, vx, 0, 0, 0, 0, 0, 0, 0))
        if switch and k == 3 and rig.ap.mode != OFFBOARD:
            rig.send_as(owner, lambda m: m.command_long_encode(1, 1, apm.MAV_CMD_DO_SET_MODE, 0, 1, 6, 0, 0, 0, 0,
                                                               0))
        rig.run(0.1)


def test_a_return_streams_velocity_first_then_switches_to_offboard_and_holds_on_link_regained():
    rig, owner = owned_px4()
    assert rig.ap.mode == HOLD
    rig.deliver = lambda gs, t: gs is not owner
    since = len(rig.ap.received)
    assert rig.run(6, lambda: rig.companion.vehicle.book.returning)
    assert rig.run(1, lambda: rig.ap.mode == OFFBOARD), "the return never got PX4 into Offboard"
    sent = rig.ap.received[since:]
    first_target = next(i for i, m in enumerate(sent) if m.get_type() == "SET_POSITION_TARGET_LOCAL_NED")
    first_switch = next(i for i, m in enumerate(sent)
                        if m.get_type() == "COMMAND_LONG" and m.command == apm.MAV_CMD_DO_SET_MODE)
    assert first_target < first_switch and rig.ap.refusals == 0  # the stream ran before the switch: never refused
    switch = sent[first_switch]
    assert (switch.param2, switch.param3) == (6, 0)  # PX4's main mode Offboard, as params 2 and 3
    before = len(rig.ap.received)
    rig.run(1)
    targets = rig.ap.sent("SET_POSITION_TARGET_LOCAL_NED", before)
    assert 8 <= len(targets) <= 12  # 10 Hz: PX4 leaves Offboard when the stream stops for COM_OF_LOSS_T
    assert all(math.hypot(m.vx, m.vy) > 0 for m in targets)  # never (0, 0): that is "bearing north" to PX4
    # the route lies behind: first an about-turn to the heading behind (NED; no reverse in Offboard) ...
    assert targets[0].coordinate_frame == apm.MAV_FRAME_LOCAL_NED and targets[0].vx < 0
    assert rig.run(3, lambda: rig.ap.x < 19.0)
    before = len(rig.ap.received)
    rig.run(0.5)
    ahead = rig.ap.sent("SET_POSITION_TARGET_LOCAL_NED", before)  # ... then speed and bearing in the body frame
    assert ahead and all(m.coordinate_frame == apm.MAV_FRAME_BODY_NED and m.vx > 0.5 for m in ahead)
    rig.deliver = lambda gs, t: True
    assert rig.run(6, lambda: not rig.companion.vehicle.book.returning)
    assert rig.run(1, lambda: rig.ap.mode == HOLD)
    assert rig.companion.vehicle.event_log[-1].reason is ExpireReason.LINK_REGAINED


def test_the_owners_offboard_stream_stopping_is_held_by_the_dead_man():
    rig, owner = owned_px4()
    owner_streaming(rig, owner, 2.0)
    assert rig.ap.mode == OFFBOARD and rig.ap.speed > 0.5
    rig.ap.typed["COM_OF_LOSS_T"] = (60.0, REAL32)  # PX4's own Offboard loss out of the way: the companion's turn
    rig.deliver = lambda gs, t: gs is not owner
    silent_at = rig.t
    assert rig.run(2, lambda: rig.ap.mode == HOLD), "the dead-man never held the owner's drive"
    assert rig.t - silent_at <= 1.0 + 0.2  # LNK_HOLD_S, not LNK_TIMEOUT
    assert rig.companion.counters["drive_held"] == 1 and not rig.companion.vehicle.book.returning
    assert rig.run(3, lambda: rig.companion.vehicle.book.returning)
    assert rig.run(1, lambda: rig.ap.mode == OFFBOARD)  # the return takes it from Hold


def test_px4_leaving_the_owners_offboard_as_the_return_begins_does_not_end_the_return():
    rig, owner = owned_px4(params=Params({"LNK_HOLD_S": 0.0}))
    rig.ap.typed["COM_OF_LOSS_T"] = (60.0, REAL32)  # the stand-in leaves Offboard when the test says
    owner_streaming(rig, owner, 2.0)
    rig.deliver = lambda gs, t: gs is not owner
    assert rig.run(6, lambda: rig.companion.driver.engaged)
    assert rig.companion.driver.seen.mode == OFFBOARD  # the owner's Offboard, as the companion last heard it
    rig.ap.mode = HOLD  # PX4's Offboard loss of the owner's dead stream, told by its next heartbeat
    assert rig.run(2, lambda: rig.ap.mode == OFFBOARD)  # the companion's own Offboard
    rig.run(1)
    assert rig.companion.vehicle.book.returning and rig.ap.mode == OFFBOARD


def test_after_a_hold_in_a_radio_hole_the_owners_next_setpoint_has_the_companion_resume_offboard():
    rig, owner = owned_px4()
    owner_streaming(rig, owner, 2.0)
    assert rig.ap.mode == OFFBOARD
    rig.deliver = lambda gs, t: gs is not owner  # a hole longer than COM_OF_LOSS_T, shorter than LNK_TIMEOUT
    assert rig.run(2, lambda: rig.ap.mode == HOLD)
    rig.deliver = lambda gs, t: True
    since = len(rig.ap.received)
    owner_streaming(rig, owner, 1.0, switch=False)  # the owner's stream again, and no mode change from it
    switches = [m for m in rig.ap.sent("COMMAND_LONG", since) if m.command == apm.MAV_CMD_DO_SET_MODE]
    assert rig.ap.mode == OFFBOARD and rig.ap.speed > 0.5
    assert switches and all(m.get_srcComponent() == 191 for m in switches)  # the companion's, who knows the lease
    assert not rig.companion.vehicle.book.returning and len(rig.companion.vehicle.event_log) == 1


def test_a_dead_companion_mid_return_ends_in_px4s_offboard_loss_hold():
    rig, owner = owned_px4()
    rig.deliver = lambda gs, t: gs is not owner
    assert rig.run(7, lambda: rig.ap.mode == OFFBOARD)
    rig.companion.tick = lambda t: None  # hung: no more targets, no keepalive
    dead_at = rig.t
    assert rig.run(3, lambda: rig.ap.mode == HOLD)
    assert rig.t - dead_at <= rig.ap.param("COM_OF_LOSS_T") + 0.1 and rig.ap.speed == 0.0


# ----- PX4's setpoints and parameters ----------------------------------------------------------------------------
def test_a_velocity_target_is_a_speed_and_a_bearing_as_px4s_rover_reads_it():
    enc = apm.MAVLink(None, 1, 191)
    stop = px4.velocity_target(enc, 1, 1, 0.0, 0.0, 0.1)
    assert stop.coordinate_frame == apm.MAV_FRAME_BODY_NED and 0 < stop.vx < 0.01 and stop.vy == 0
    left = px4.velocity_target(enc, 1, 1, 1.5, 1.0, 0.1)
    lead = math.atan2(left.vy, left.vx)
    assert math.hypot(left.vx, left.vy) == pytest.approx(1.5) and lead > 0.1  # a bearing ahead of the turn
    # PX4's yaw loop (P = RO_YAW_P) closes that lead exponentially: over one period it turns the commanded rate
    assert lead * (1 - math.exp(-0.1 * px4.YAW_P)) == pytest.approx(1.0 * 0.1)
    back = px4.velocity_target(enc, 1, 1, -1.0, 0.0, 0.1)
    assert back.vx == pytest.approx(-1.0)  # no reverse in Offboard: the bearing behind, driven forward
    assert px4.bearing_lead(100.0, 0.1) == px4.MAX_LEAD


@pytest.mark.parametrize("value, ptype", [(1, INT32), (5, INT32), (-1, INT32), (0, INT32), (0.5, REAL32)])
def test_px4_parameters_travel_bytewise(value, ptype):
    wire = px4.param_wire(value, ptype)
    assert px4.param_value(wire, ptype) == value
    if ptype == INT32 and value:
        assert wire != value  # not ArduPilot's cast


def test_the_px4_table_and_what_configure_sets_from_px4s_defaults():
    defaults = {name: v for name, (v, _) in PX4_DEFAULTS.items()}
    assert [r.need.name for r in differing(check(defaults, PX4_NEEDS))] == [
        "NAV_DLL_ACT", "COM_DL_LOSS_T", "COM_OF_LOSS_T", "COM_OBL_RC_ACT"]
    fixed = configured(defaults)
    assert (fixed["NAV_DLL_ACT"], fixed["COM_DL_LOSS_T"], fixed["COM_OF_LOSS_T"], fixed["COM_OBL_RC_ACT"]) == (
        1, 5, 0.5, 5)
    assert not differing(check(fixed, PX4_NEEDS))
    assert not differing(check(px4_companion_params(1.5), PX4_NEEDS))  # the plant starts from a configured PX4


def test_check_and_configure_name_and_set_px4s_parameters(capsys):
    ap = FakePX4()
    ap.locked.add("COM_OBL_RC_ACT")  # one PX4 will not take: reported, not a traceback
    server = FakeAutopilotServer(ap)
    try:
        code = main(["companion", "--autopilot", f"tcp:127.0.0.1:{server.port}", "--check", "--wait", "5"])
        out = capsys.readouterr().out
        assert code == 1 and "NAV_DLL_ACT" in out and "FS_GCS_ENABLE" not in out
        assert [ln.split()[0] for ln in out.splitlines() if "DIFFERS" in ln] == [
            "NAV_DLL_ACT", "COM_DL_LOSS_T", "COM_OF_LOSS_T", "COM_OBL_RC_ACT"]
        assert ap.param("NAV_DLL_ACT") == 0  # --check never changes anything
        code = main(["companion", "--autopilot", f"tcp:127.0.0.1:{server.port}", "--configure", "--wait", "5"])
        captured = capsys.readouterr()
        assert code == 1 and "Traceback" not in captured.err
        assert "set NAV_DLL_ACT 0 -> 1" in captured.out and "set COM_OF_LOSS_T 1 -> 0.5" in captured.out
        assert "did not take COM_OBL_RC_ACT = 5" in captured.err
        # bytewise, in the parameter's own type: the stand-in (as PX4) ignores anything else
        assert (ap.param("NAV_DLL_ACT"), ap.param("COM_DL_LOSS_T"), ap.param("COM_OF_LOSS_T")) == (1, 5, 0.5)
        ap.locked.clear()
        assert main(["companion", "--autopilot", f"tcp:127.0.0.1:{server.port}", "--configure", "--wait", "5"]) == 0
        assert "the autopilot is set up for companion mode" in capsys.readouterr().out
    finally:
        server.close()


def test_companion_flies_beside_both_autopilots():
    assert flies("companion", "px4rover") and flies("companion", "ardurover") and not flies("companion", "rover")
    assert plant_for("px4rover", "companion") is PX4CompanionPlant


# ----- the real PX4 ------------------------------------------------------------------------------------------------
def tunnel(duration: float) -> str:
    text = (ROOT / "sim" / "scenarios" / "tunnel.toml").read_text(encoding="utf-8")
    return "\n".join(f"duration = {duration}" if line.startswith("duration =") else line
                     for line in text.splitlines()) + "\n"


def test_the_companion_returns_px4_in_offboard_and_leaves_it_in_hold(tmp_path, monkeypatch, capsys):
    px4_dir = px4_or_skip()
    started = Started(monkeypatch)
    scenario = tmp_path / "tunnel.toml"
    scenario.write_text(tunnel(60.0))
    out = tmp_path / "out"
    code = main(["sim", "run", str(scenario), "--vehicle", "px4rover", "--policy", "companion", "--px4",
                 str(px4_dir), "--quiet", "--out", str(out)])
    printed = capsys.readouterr().out
    assert started.all_gone()
    m = json.loads((out / "metrics.json").read_text())
    assert code == (0 if m["passed"] else 1), printed
    assert (out / "trajectory.png").stat().st_size > 0 and (out / "timeline.png").stat().st_size > 0
    assert m["vehicle"] == "px4rover" and m["policy"] == "companion" and m["firmware"].startswith("PX4 v")
    reasons = [e["reason"] for e in m["lease_events"]]
    # The first loss and its return are what PX4 and the companion guarantee. What follows the operator's claim
    # varies from run to run with PX4's own threads (when its Offboard takes the operator's drive again; a drive on
    # along the fringe lost the link once more in about one run of twelve): any later loss, each ended by a return
    # of its own or still running when the run ends, none touching a wall (collisions_during_return below).
    assert reasons[:3] == ["NONE", "COMMS_LOST", "LINK_REGAINED"], m["lease_events"]
    later = reasons[3:]
    assert all(r in ("COMMS_LOST", "LINK_REGAINED", "COMPLETED") for r in later), m["lease_events"]
    assert later[::2] == ["COMMS_LOST"] * len(later[::2]), m["lease_events"]  # each loss, then its return's end
    assert "COMMS_LOST" not in later[1::2], m["lease_events"]
    assert m["regained_by"] == "return" and m["collisions_during_return"] == 0 and m["stale_commands_executed"] == 0
    block = m["blocks"][0]
    assert block["command"] == "RETURN_TO_LINK" and block["distance_m"] > 1.0
    modes = [(e["t"], e["mode"]) for e in m["firmware_modes"]]
    # driven out in Offboard; Hold once the owner's stream stopped; the return's own Offboard; at the regain its zero
    # setpoints, then Hold once the rover stands, unless the operator claimed and drove on first (its stream ends the
    # brake, as beside ArduPilot: measured, in 60 s it always had)
    during = [name for t, name in modes if block["start_s"] - 0.05 <= t <= block["end_s"] + 0.05]
    assert "OFFBOARD" in during, modes
    after = [name for t, name in modes if t > block["end_s"]]
    assert set(after) <= {"AUTO_LOITER", "OFFBOARD"} and modes[-1][1] == "OFFBOARD", modes  # the operator drives on
    assert m["link_regained_s"] - m["link_lost_s"] < 8.0


class KilledMidReturn(PX4CompanionPlant):
    """The companion dies ``after`` s into its return once PX4 is in Offboard: no frame leaves it any more, PX4
    keeps running. Before that, PX4's parameters are read and one written through the companion's driver: the
    real encoding. ``killed``: when it died."""

    after = 1.0

    def __init__(self, *a, **kw) -> None:
        super().__init__(*a, **kw)
        self.killed: float | None = None
        self.asked = self.wrote = False

    def tick(self, t: float) -> None:
        d = self.companion.driver
        if not self.asked and self.vehicle is not None:
            self.asked = True
            for name in ("NAV_DLL_ACT", "COM_OF_LOSS_T", "COM_DL_LOSS_T"):
                d.send_message(d.enc.param_request_read_encode(d.seen.sysid, d.seen.compid, name.encode(), -1))
        if not self.wrote and t >= 6.0:  # as --configure writes (bytewise INT32): COM_DL_LOSS_T 5 -> 4, read back
            self.wrote = True
            wire = d.rules.param_wire(4, d.seen.param_types.get("COM_DL_LOSS_T", INT32))
            d.send_message(d.enc.param_set_encode(d.seen.sysid, d.seen.compid, b"COM_DL_LOSS_T", wire, INT32))
        if self.killed is not None:
            return
        v = self.vehicle
        block = v is not None and v.book.returning and v.event_log and v.event_log[-1].t
        if block and self.link.tap.mode == OFFBOARD and t - block >= self.after:
            self.killed = t
            return
        super().tick(t)

    def frames(self, t: float) -> list[bytes]:
        out = super().frames(t)
        return [] if self.killed is not None else out

    def receive(self, frames, t: float) -> None:
        if self.killed is None:
            super().receive(frames, t)

    def _to_autopilot(self, data: bytes) -> None:
        if self.killed is None:
            super()._to_autopilot(data)


def killed_run(px4_dir: Path, **params) -> tuple[Run, KilledMidReturn]:
    """The tunnel with the companion killed mid-return (``params``: PX4's, on top of the companion run's)."""
    sc = parse(tunnel(60.0), "tunnel.toml")
    plant = type("Killed", (KilledMidReturn,), {"_px4_params": staticmethod(
        lambda policy, lnk, speed: {**px4_companion_params(speed), **params})})
    run = Run(sc, "px4rover", 1, policy="companion", px4=px4_dir, plant=plant, duration=55.0).run()
    run.metrics = metrics.compute(run)
    return run, run.plant


def hold_after_kill(plant: KilledMidReturn) -> float | None:
    """Seconds from the kill to PX4's Hold (None: never, or it left Hold again)."""
    modes = [(t, m) for t, m in plant.link.tap.modes if t > plant.killed]
    if not modes or any(m != HOLD for _, m in modes):
        return None
    return modes[0][0] - plant.killed


def test_a_companion_killed_mid_return_leaves_px4_in_its_own_hold(monkeypatch):
    px4_dir = px4_or_skip()
    started = Started(monkeypatch)
    run, plant = killed_run(px4_dir)
    assert started.all_gone()
    assert plant.killed is not None, "the return never got PX4 into Offboard"
    of_loss = plant.params["COM_OF_LOSS_T"]
    took = hold_after_kill(plant)
    names = [(round(t, 2), nav_state_name(m)) for t, m in plant.link.tap.modes]
    assert took is not None and took <= of_loss + 2.0, names  # PX4's Offboard loss, COM_OBL_RC_ACT 5: Hold
    # (PX4 says so within COM_OF_LOSS_T; its heartbeat, once a second, shows the Hold up to a second later)
    texts = plant.link.tap.texts
    assert any("Failsafe" in text and plant.killed < t <= plant.killed + of_loss + 0.5 for t, text in texts)
    # at rest, near where it died: PX4's Hold stops the rover (and drives it back to the point where Hold began
    # if it stopped past it: measured 0.4 m)
    at_kill = next(r for r in plant.rows if r[0] >= plant.killed)
    last = [r for r in plant.rows if r[0] >= plant.rows[-1][0] - 3.0]
    assert all(r[8] == 0.0 and math.dist(r[1:3], last[-1][1:3]) < 0.01 for r in last)
    assert math.dist(at_kill[1:3], last[-1][1:3]) < 2.0
    # the real PX4's parameters through the companion's driver: bytewise INT32, REAL32, and a write read back
    seen = plant.companion.driver.seen
    assert (seen.params["NAV_DLL_ACT"], seen.param_types["NAV_DLL_ACT"]) == (1, INT32)
    assert (seen.params["COM_OF_LOSS_T"], seen.param_types["COM_OF_LOSS_T"]) == (0.5, REAL32)
    assert seen.params["COM_DL_LOSS_T"] == 4
    assert plant.companion.driver.rules is PX4Rules
