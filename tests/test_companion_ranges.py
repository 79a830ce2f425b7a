"""The rover's range data as the companion's range sensor (docs/architecture.md §11.4, ``vehicle.companion.ranges``):
DISTANCE_SENSOR and OBSTACLE_DISTANCE converted to beams, bad fields dropped and counted, each reading used once,
stale ones never; the driver hears them from any component of the autopilot's system; the standoff remembers a few
rangefinders' beams for a moment; with none heard the companion reads as before and says so once."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as apm

from tests.companion_rig import FakeAutopilot, Rig
from vehicle.companion.autopilot import AutopilotDriver
from vehicle.companion.ranges import QUIET_S, UINT16_MAX, Beam, RangeSensors, distance_beam, obstacle_beams
from vehicle.companion.setup import range_params, range_report
from vehicle.standoff import MAX_AGE, MEMORY, SPARSE, Sweep, remember

OBSTACLE_AVOIDANCE = apm.MAV_COMP_ID_OBSTACLE_AVOIDANCE


def distance(current: int, orientation: int = apm.MAV_SENSOR_ROTATION_NONE, low: int = 5, high: int = 800,
             quaternion=(0.0, 0.0, 0.0, 0.0), quality: int = 0, sensor: int = 0):
    return apm.MAVLink_distance_sensor_message(0, low, high, current, apm.MAV_DISTANCE_SENSOR_LASER, sensor,
                                               orientation, 0, 0.0, 0.0, quaternion, quality)


def obstacle(distances, increment: int = 5, low: int = 10, high: int = 1000, increment_f: float = 0.0,
             offset: float = 0.0, frame: int = apm.MAV_FRAME_BODY_FRD):
    d = list(distances) + [UINT16_MAX] * (72 - len(distances))
    return apm.MAVLink_obstacle_distance_message(0, apm.MAV_DISTANCE_SENSOR_LASER, d, increment, low, high,
                                                 increment_f, offset, frame)


def framed(msg, sysid: int = 1, compid: int = 1):
    """``msg`` as it arrives: packed by (sysid, compid) and parsed back (so it knows its sender)."""
    enc = apm.MAVLink(None, sysid, compid)
    parser = apm.MAVLink(None, 0, 0)
    return parser.parse_buffer(bytes(msg.pack(enc)))[0]


def yaw_quaternion(deg: float, pitch_deg: float = 0.0) -> tuple[float, float, float, float]:
    """(w, x, y, z) of a yaw then a pitch (body -> sensor), as the rotation a DISTANCE_SENSOR's CUSTOM names."""
    y, p = math.radians(deg) / 2, math.radians(pitch_deg) / 2
    # q = q_yaw * q_pitch
    return (math.cos(y) * math.cos(p), -math.sin(y) * math.sin(p), math.cos(y) * math.sin(p),
            math.sin(y) * math.cos(p))


# ----- DISTANCE_SENSOR ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("orientation,bearing", [
    (apm.MAV_SENSOR_ROTATION_NONE, 0.0), (apm.MAV_SENSOR_ROTATION_YAW_45, 45.0), (apm.MAV_SENSOR_ROTATION_YAW_90, 90.0),
    (apm.MAV_SENSOR_ROTATION_YAW_180, 180.0), (apm.MAV_SENSOR_ROTATION_YAW_270, -90.0),
    (apm.MAV_SENSOR_ROTATION_YAW_315, -45.0), (apm.MAV_SENSOR_ROTATION_ROLL_180_YAW_90, 90.0),
    (apm.MAV_SENSOR_ROTATION_PITCH_180, 180.0)])
def test_a_horizontal_rangefinder_is_a_beam_at_its_yaw_clockwise_from_ahead(orientation, bearing):
    b = distance_beam(distance(250, orientation))
    assert isinstance(b, Beam)
    assert math.isclose(math.remainder(b.bearing - math.radians(bearing), math.tau), 0.0, abs_tol=1e-9)
    assert b.range == pytest.approx(2.5) and b.reach == pytest.approx(8.0)


@pytest.mark.parametrize("orientation,why", [
    (apm.MAV_SENSOR_ROTATION_PITCH_270, "not horizontal"), (apm.MAV_SENSOR_ROTATION_PITCH_90, "not horizontal"),
    (200, "unknown orientation")])
def test_a_rangefinder_that_looks_up_down_or_nowhere_known_is_dropped(orientation, why):
    assert distance_beam(distance(250, orientation)) == why


def test_a_custom_orientation_takes_its_quaternion():
    b = distance_beam(distance(300, apm.MAV_SENSOR_ROTATION_CUSTOM, quaternion=yaw_quaternion(30.0)))
    assert isinstance(b, Beam) and math.degrees(b.bearing) == pytest.approx(30.0)
    assert distance_beam(distance(300, apm.MAV_SENSOR_ROTATION_CUSTOM)) == "bad quaternion"  # all zero: invalid
    assert distance_beam(distance(300, apm.MAV_SENSOR_ROTATION_CUSTOM,
                                  quaternion=yaw_quaternion(30.0, pitch_deg=45.0))) == "not horizontal"
    assert distance_beam(distance(300, apm.MAV_SENSOR_ROTATION_CUSTOM,
                                  quaternion=(math.nan, 0.0, 0.0, 1.0))) == "bad quaternion"


def test_beyond_its_maximum_a_rangefinder_saw_nothing_within_its_reach():
    b = distance_beam(distance(900))  # max 800 cm: ArduPilot's out-of-range-high
    assert isinstance(b, Beam) and b.range == math.inf and b.reach == pytest.approx(8.0)


@pytest.mark.parametrize("msg,why", [
    (distance(UINT16_MAX), "unknown distance"), (distance(3), "below minimum"),
    (distance(250, quality=1), "invalid signal"), (distance(250, low=900, high=800), "bad limits"),
    (distance(250, high=0), "bad limits")])
def test_a_reading_that_says_nothing_true_is_dropped_with_its_reason(msg, why):
    assert distance_beam(msg) == why


# ----- OBSTACLE_DISTANCE -------------------------------------------------------------------------------------------
def test_sectors_in_the_body_frame_are_beams_from_the_offset_by_the_increment_unknown_ones_left_out():
    beams = obstacle_beams(obstacle([100, UINT16_MAX, 1001, 300], increment=10, offset=-10.0), yaw=None)
    assert [round(math.degrees(b.bearing)) for b in beams] == [-10, 10, 20]
    assert [b.range for b in beams] == [pytest.approx(1.0), math.inf, pytest.approx(3.0)]  # 1001: max + 1, nothing
    assert all(b.reach == pytest.approx(10.0) for b in beams)


def test_increment_f_wins_over_the_whole_degrees_and_only_a_circle_of_sectors_counts():
    beams = obstacle_beams(obstacle([200] * 72, increment=5, increment_f=7.5), yaw=None)
    assert len(beams) == 48  # 360 / 7.5
    assert math.degrees(beams[1].bearing) == pytest.approx(7.5)


def test_north_aligned_sectors_are_turned_into_the_heading_and_need_it():
    beams = obstacle_beams(obstacle([200], frame=apm.MAV_FRAME_LOCAL_NED), yaw=math.radians(90.0))
    assert math.degrees(beams[0].bearing) == pytest.approx(-90.0)  # north lies to the left of an east-facing rover
    assert obstacle_beams(obstacle([200], frame=apm.MAV_FRAME_GLOBAL), yaw=None) == "no heading"


@pytest.mark.parametrize("msg,why", [
    (obstacle([200], increment=0), "bad increment"), (obstacle([200], increment=0, increment_f=-5.0), "bad increment"),
    (obstacle([200], offset=math.nan), "bad angle"), (obstacle([200], frame=apm.MAV_FRAME_MISSION), "unknown frame"),
    (obstacle([200], low=500, high=100), "bad limits")])
def test_a_sector_message_without_a_usable_geometry_is_dropped_with_its_reason(msg, why):
    assert obstacle_beams(msg, yaw=0.0) == why


def test_sectors_below_the_minimum_are_left_out():
    beams = obstacle_beams(obstacle([5, 200], low=10), yaw=None)
    assert len(beams) == 1 and beams[0].range == pytest.approx(2.0)


# ----- the readings as scans ---------------------------------------------------------------------------------------
def test_each_reading_is_in_one_scan_only_and_a_stale_one_in_none():
    r = RangeSensors()
    r.heard(framed(distance(250)), 1.0, 0.0)
    r.heard(framed(distance(400, apm.MAV_SENSOR_ROTATION_YAW_90, sensor=1)), 1.0, 0.0)
    s = r.scan(1.02)
    assert s is not None and sorted(s.ranges) == [pytest.approx(2.5), pytest.approx(4.0)] and s.max_range == 8.0
    assert r.scan(1.04) is None  # used once
    r.heard(framed(distance(250)), 2.0, 0.0)
    assert r.scan(2.0 + MAX_AGE + 0.1) is None  # waited too long: says nothing of now
    assert r.counts["stale"] == 1 and r.counts["messages"] == 3 and r.counts["beams"] == 3


def test_bad_messages_are_counted_by_reason_and_never_raise():
    r = RangeSensors()
    r.heard(framed(distance(UINT16_MAX)), 1.0, 0.0)
    r.heard(framed(distance(250, apm.MAV_SENSOR_ROTATION_PITCH_270)), 1.0, 0.0)
    r.heard(framed(obstacle([200], increment=0)), 1.0, 0.0)
    assert r.counts == {"unknown distance": 1, "not horizontal": 1, "bad increment": 1}
    assert r.scan(1.0) is None and r.first_heard is None


def test_a_shorter_sensor_that_saw_nothing_is_left_out_of_a_longer_reach():
    r = RangeSensors()
    r.heard(framed(obstacle([200, 1001])), 1.0, 0.0)  # a 10 m lidar
    r.heard(framed(distance(900, high=400)), 1.0, 0.0)  # a 4 m rangefinder that saw nothing: not "nothing to 10 m"
    s = r.scan(1.0)
    assert s.max_range == pytest.approx(10.0) and len(s.ranges) == 2


# ----- the driver ---------------------------------------------------------------------------------------------------
def driver_heard() -> AutopilotDriver:
    d = AutopilotDriver(lambda b: None)
    d.observe(framed(apm.MAVLink_heartbeat_message(apm.MAV_TYPE_GROUND_ROVER, apm.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0,
                                                   0, 3)), 0.0)
    return d


def test_the_driver_reads_range_data_from_any_component_of_the_autopilots_system_and_no_other():
    d = driver_heard()
    d.observe(framed(distance(250)), 1.0)  # the autopilot's rangefinder
    d.observe(framed(obstacle([150] * 72), compid=OBSTACLE_AVOIDANCE), 1.0)  # a lidar driver on the vehicle
    d.observe(framed(distance(100), sysid=7), 1.0)  # another vehicle's
    scan = d.read(1.02, 0.02).scan
    assert scan is not None and len(scan.ranges) == 73 and min(scan.ranges) == pytest.approx(1.5)
    assert d.ranges.sources == {(1, 1, "DISTANCE_SENSOR"), (1, OBSTACLE_AVOIDANCE, "OBSTACLE_DISTANCE")}


def test_without_range_data_the_driver_reads_no_scan_as_before():
    d = driver_heard()
    assert d.read(1.0, 0.02).scan is None


def test_the_companion_asks_the_autopilot_for_its_rangefinders():
    from vehicle.companion.px4 import STREAMS as PX4_STREAMS
    from vehicle.companion.rules import STREAMS

    assert STREAMS[apm.MAVLINK_MSG_ID_DISTANCE_SENSOR] <= 100_000
    assert PX4_STREAMS[apm.MAVLINK_MSG_ID_DISTANCE_SENSOR] <= 100_000


# ----- the standoff's memory of a few beams --------------------------------------------------------------------------
def points(n: int, t: float, x0: float = 1.0) -> Sweep:
    return Sweep(np.full(n, x0), np.arange(n, dtype=float), t)


def test_a_few_beams_are_remembered_for_a_moment_and_a_full_sweep_replaces():
    kept = remember(None, points(6, 0.0), 6)
    kept = remember(kept, points(6, 0.5, x0=2.0), 6)
    assert len(kept.x) == 12 and kept.t == 0.5
    kept = remember(kept, points(6, MEMORY + 0.1, x0=3.0), 6)
    assert len(kept.x) == 12 and set(kept.x) == {2.0, 3.0}  # the first six are older than MEMORY
    full = points(SPARSE, 2.0)
    assert remember(kept, full, SPARSE) is full  # a lidar's sweep: exactly as before
    assert remember(kept, None, 6) is None  # a scan that is not numbers: nothing kept, as before


# ----- the companion: said once --------------------------------------------------------------------------------------
class RangingAutopilot(FakeAutopilot):
    """The stand-in autopilot with a forward rangefinder that sees a wall 1.5 m ahead, at 10 Hz."""

    def step(self, t, dt):
        if t >= getattr(self, "next_range", 0.0):
            self.next_range = t + 0.1
            self._send(distance(150))
        return super().step(t, dt)


def notices(rig: Rig) -> list[str]:
    return [m.text for m in rig.ground_messages("STATUSTEXT")]


def test_with_no_range_sensor_the_companion_reads_as_before_and_says_so_once():
    rig = Rig()
    scans = []
    rig.run(QUIET_S + 8.0)
    v = rig.companion.vehicle
    assert v is not None
    scans.append(v.control.readings.scan)
    said = [n for n in notices(rig) if "range sensor" in n]
    assert said == ["no range sensor heard: return keeps no standoff"]
    assert scans == [None] and v.control.sweep is None and v.control.free.scans == 0


def test_a_rangefinder_heard_is_said_once_and_fed_to_the_standoff():
    rig = Rig(autopilot=RangingAutopilot())
    rig.run(QUIET_S + 3.0)
    v = rig.companion.vehicle
    said = [n for n in notices(rig) if "range sensor" in n]
    assert len(said) == 1 and said[0].startswith("range sensor heard (DISTANCE_SENSOR from 1/1)")
    assert v.control.sweep is not None and v.control.free.scans > 0
    assert np.hypot(v.control.sweep.x - v.estimator.pose.x, v.control.sweep.y).min() == pytest.approx(1.5, abs=0.05)
    relayed = [m for m in rig.ground_messages("DISTANCE_SENSOR")]
    assert 0 < len(relayed) <= QUIET_S + 4  # once a second to the ground, not the 10 Hz the return reads


# ----- --check -------------------------------------------------------------------------------------------------------
def test_check_names_the_rangefinders_that_give_the_return_its_standoff_and_the_ones_that_do_not():
    assert {"RNGFND1_TYPE", "RNGFND1_ORIENT", "RNGFND6_ORIENT", "PRX1_TYPE"} <= set(range_params(3))
    text = range_report({"RNGFND1_TYPE": 100, "RNGFND1_ORIENT": 0, "RNGFND2_TYPE": 10, "RNGFND2_ORIENT": 25}, 3)
    assert "RNGFND1_ORIENT 0: facing forward" in text and "RNGFND2_ORIENT 25: not along the ground" in text
    assert "MAVn_EXTRA3" in text and "keeps no standoff" not in text
    assert "keeps no standoff" in range_report({"RNGFND1_TYPE": 0, "PRX1_TYPE": 0}, 3)
    assert "keeps no standoff" not in range_report({"PRX1_TYPE": 2}, 3)
    assert "SENS_EN_SF1XX 4" in range_report({"SENS_EN_SF1XX": 4}, 12)
    assert "keeps no standoff" in range_report({}, 12)


# ----- the simulated rover's sensors, as the companion hears them --------------------------------------------------
def walled():
    """A world with a wall 2.75 m ahead of a rover at the origin facing north (its face: 3 m less half its 0.5 m)."""
    from sim.robots import Rover
    from sim.world import Wall, World

    world = World((Wall(((3.0, -5.0), (3.0, 5.0)), 0.5, 10.0),))
    return world, Rover(world, 0.0, 0.0, 0.0, np.random.default_rng(0))


def test_the_firmwares_rangefinders_see_the_wall_ahead_and_nothing_behind():
    import json

    from sim.firmware import rangefinders as rf
    from sim.firmware.bridge import state_reply

    world, _ = walled()
    ranges = rf.Rangefinders(world, np.random.default_rng(1)).measure(0.0, 0.0, 0.0, 0.0)
    assert ranges[0] == pytest.approx(2.75, abs=0.1) and ranges[rf.BEARINGS.index(math.pi)] == rf.REACH + 1.0
    reply = state_reply(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, ranges)
    assert f'"rng_1":{ranges[0]:.3f}'.encode() in reply  # (the firmware finds each value right after its key)
    assert json.loads(reply)["rng_6"] == pytest.approx(ranges[5], abs=1e-3)
    assert b"rng_" not in state_reply(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # a rover without: as before
    p = rf.params()
    assert [p[f"RNGFND{n}_ORIENT"] for n in range(1, 7)] == list(rf.ORIENT)
    assert all(p[f"RNGFND{n}_TYPE"] == rf.SITL_TYPE for n in range(1, 7))


def custom_copy(m):
    """``m`` with its orientation CUSTOM, as PX4 reports a sensor that is not forward, back, left or right."""
    return apm.MAVLink_distance_sensor_message(m.time_boot_ms, m.min_distance, m.max_distance, m.current_distance,
                                               m.type, m.id, apm.MAV_SENSOR_ROTATION_CUSTOM, m.covariance,
                                               m.horizontal_fov, m.vertical_fov, m.quaternion, m.signal_quality)


def test_px4s_distance_sensors_are_read_back_as_the_same_beams():
    from sim.firmware import rangefinders as rf

    world, _ = walled()
    ranges = rf.Rangefinders(world, np.random.default_rng(1)).measure(0.0, 0.0, 0.0, 0.0)
    sent = rf.distance_sensors(ranges, 1000)
    beams = [distance_beam(framed(m)) for m in sent]
    # PX4 reports the diagonals as CUSTOM with the quaternion it was given: the companion reads them the same
    custom = [distance_beam(framed(custom_copy(m))) for m in sent]
    assert all(abs(math.remainder(c.bearing - b.bearing, math.tau)) < 1e-6 for c, b in zip(custom, beams, strict=True))
    assert [round(math.degrees(b.bearing)) % 360 for b in beams] == [round(math.degrees(a)) % 360 for a in rf.BEARINGS]
    assert beams[0].range == pytest.approx(ranges[0], abs=0.01) and beams[3].range == math.inf


def test_the_lidar_drivers_sweep_is_the_native_sensors_sweep_to_the_companion():
    from sim.plants.lidar import COMPID, Lidar

    world, robot = walled()
    lidar = Lidar(world, robot, np.random.default_rng(2))
    parser = apm.MAVLink(None, 0, 0)
    m = parser.parse_buffer(lidar.frame(0.0, 1))[0]
    assert (m.get_srcSystem(), m.get_srcComponent()) == (1, COMPID) and not lidar.due(0.1) and lidar.due(0.5)
    r = RangeSensors()
    r.heard(m, 0.0, None)
    s = r.scan(0.0)
    assert len(s.ranges) == 72 and s.max_range == pytest.approx(8.0)
    assert s.ranges[0] == pytest.approx(2.75, abs=0.1) and s.ranges[36] == math.inf  # ahead the wall, behind nothing
