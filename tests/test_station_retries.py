"""The ground station resends an unanswered command every COMMAND_RETRY seconds, COMMAND_TRIES times in all, each
command on its own schedule, and never one that was answered (its tick skips the walk when no retry is due)."""

from __future__ import annotations

from gcs.station import COMMAND_RETRY, COMMAND_TRIES, GroundStation, mav


def _commands(frames: list[bytes]) -> list[tuple[int, int]]:
    parser = mav.MAVLink(None, 0, 0)
    out = []
    for data in frames:
        for m in parser.parse_buffer(data) or []:
            if m.get_type() == "COMMAND_LONG":
                out.append((m.command, m.confirmation))
    return out


def _ack(gs: GroundStation, command: int, t: float) -> None:
    vehicle = mav.MAVLink(None, 1, 1)
    gs.feed(vehicle.command_ack_encode(command, mav.MAV_RESULT_ACCEPTED).pack(vehicle), t)


def test_unanswered_commands_are_resent_on_their_own_schedules_and_answered_ones_are_not():
    gs = GroundStation(255, 190)
    sent: list[tuple[float, int, int]] = []
    arm = rtl = None
    for k in range(0, 400):  # 8 s of 50 Hz ticks
        t = k / 50
        gs.t = t
        if k == 0:
            arm = gs.arm(True)
        if k == 25:
            rtl = gs.rtl()
        if k == 160:  # the vehicle answers the RTL after its third send
            _ack(gs, mav.MAV_CMD_NAV_RETURN_TO_LAUNCH, t)
        sent += [(t, c, n) for c, n in _commands(gs.tick(t))]  # this tick's sends and the commands' first
    arms = [(t, n) for t, c, n in sent if c == mav.MAV_CMD_COMPONENT_ARM_DISARM]
    rtls = [(t, n) for t, c, n in sent if c == mav.MAV_CMD_NAV_RETURN_TO_LAUNCH]
    assert arms == [(k * COMMAND_RETRY, k) for k in range(COMMAND_TRIES)]
    assert rtls == [(0.5, 0), (1.5, 1), (2.5, 2)]
    assert arm.done and arm.result is None and arm.tries == COMMAND_TRIES
    assert rtl.done and rtl.ok
