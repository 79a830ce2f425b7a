"""The telemetry service alone: what streams at which rate, who may change a rate, a composition's own streams."""

from __future__ import annotations

from collections import Counter

from link.mission import Origin
from tests.service_kit import OWNER, STRANGER, Kit, texts
from vehicle.services.base import Source, mav
from vehicle.services.telemetry import DEFAULT_RATES, Telemetry

DT = 0.02


def telemetry(kit: Kit, **options) -> Telemetry:
    return Telemetry(kit.out, kit.vehicle, Origin(), 0.0, lambda: (0, 0), lambda: 0, **options)


def run(kit: Kit, tel: Telemetry, t0: float, seconds: float) -> Counter:
    """Tick for ``seconds`` from ``t0`` at 50 Hz; how many of each message went out."""
    sent: Counter = Counter()
    for k in range(round(seconds / DT)):
        tel.tick(t0 + k * DT)
        sent.update(m.get_type() for m in kit.replies())
    return sent


def interval(tel: Telemetry, msgid: int, us: float, sysid: int, t: float) -> int:
    result, _ = Telemetry.COMMANDS[mav.MAV_CMD_SET_MESSAGE_INTERVAL](tel, (msgid, us, 0, 0, 0, 0, 0),
                                                                     Source(sysid, 190), t)
    return result


def test_every_default_stream_goes_out_at_its_rate():
    kit = Kit()
    sent = run(kit, telemetry(kit), 0.0, 10.0)
    assert sent["HEARTBEAT"] == 10
    for msgid, period in DEFAULT_RATES.items():
        name = mav.mavlink_map[msgid].msgname
        assert abs(sent[name] - 10.0 / period) <= 1, (name, sent[name])


def test_a_composition_streams_only_what_it_owns():
    kit = Kit(compid=191)
    own = {mav.MAVLINK_MSG_ID_LEASE_STATUS: 0.5}
    sent = run(kit, telemetry(kit, rates=own, mav_type=mav.MAV_TYPE_ONBOARD_CONTROLLER), 0.0, 4.0)
    assert sent["LEASE_STATUS"] == 8 and sent["HEARTBEAT"] == 4
    assert not {"SYS_STATUS", "ATTITUDE", "LOCAL_POSITION_NED", "GLOBAL_POSITION_INT", "GPS_RAW_INT"} & set(sent)


def test_only_the_owner_changes_a_rate_once_somebody_owns_the_vehicle():
    kit = Kit()
    tel = telemetry(kit)
    kit.take_control(OWNER)
    assert interval(tel, mav.MAVLINK_MSG_ID_ATTITUDE, -1, STRANGER, 0.0) == mav.MAV_RESULT_DENIED
    assert "refused" in texts(kit.replies())[0]
    assert run(kit, tel, 0.0, 1.0)["ATTITUDE"] == 4
    assert interval(tel, mav.MAVLINK_MSG_ID_ATTITUDE, -1, OWNER, 1.0) == mav.MAV_RESULT_ACCEPTED
    assert run(kit, tel, 1.0, 2.0)["ATTITUDE"] == 0
    assert interval(tel, mav.MAVLINK_MSG_ID_ATTITUDE, 100_000, OWNER, 3.0) == mav.MAV_RESULT_ACCEPTED
    assert abs(run(kit, tel, 3.0, 1.0)["ATTITUDE"] - 10) <= 1


def test_a_rate_for_what_is_not_telemetry_here_or_a_negative_interval_is_denied():
    kit = Kit()
    tel = telemetry(kit)
    assert interval(tel, mav.MAVLINK_MSG_ID_PARAM_VALUE, 100_000, OWNER, 0.0) == mav.MAV_RESULT_DENIED
    assert interval(tel, mav.MAVLINK_MSG_ID_ATTITUDE, -5, OWNER, 0.0) == mav.MAV_RESULT_DENIED
