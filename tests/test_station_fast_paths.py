"""The ground station's per-frame shortcuts against what they stand for."""

from __future__ import annotations

from gcs.station import TARGETED, GroundStation, mav


def test_frames_for_another_station_are_ignored_and_untargeted_ones_handled():
    """``TARGETED`` names the types with a target_system field, so the station checks the target only there."""
    assert "COMMAND_ACK" in TARGETED and "LOCAL_POSITION_NED" not in TARGETED
    gs = GroundStation(255, 190, target=1)
    vehicle = mav.MAVLink(None, 1, 1)
    for ts, handled in ((77, False), (0, True), (255, True)):
        before = len(gs.acks)
        gs.feed(mav.MAVLink_command_ack_message(400, 0, 0, 0, ts, 190).pack(vehicle), 1.0)
        assert (len(gs.acks) == before + 1) == handled, ts
    gs.feed(mav.MAVLink_local_position_ned_message(0, 3.0, 4.0, 0.0, 0.0, 0.0, 0.0).pack(vehicle), 1.0)
    assert gs.vehicle.position == (3.0, 4.0)
