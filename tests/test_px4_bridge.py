"""PX4's HIL bridge (docs/architecture.md §10.1): the message functions alone, the bridge against a stand-in PX4 on
a socket, and the real PX4 rover SITL driving the project's rover model in lockstep: boot, an EKF2 position, arm
over MAVLink, Offboard at 1 m/s north, disarm, stop with nothing left running.

The real PX4 comes from $RETURNLINK_PX4, else from the shared tree beside the repository (../shared/px4); with
neither the tests that need it skip, and a variable that is set but unusable fails them."""

from __future__ import annotations

import math
import os
import signal
import socket
import time
from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mav

from link.mission import Origin
from sim.px4 import process
from sim.px4.bridge import BridgeError, HilBridge
from sim.px4.hil import (
    ACCEL,
    ALL_SENSORS,
    BARO,
    DIFF_PRESS,
    EARTH_RADIUS_M,
    GPS_PERIOD_US,
    GRAVITY,
    GYRO,
    MAG,
    GpsClock,
    RoverState,
    SensorNoise,
    Wheels,
    earth_field,
    gps_position,
    hil_gps,
    hil_sensor,
    pressure_hpa,
    rover_command,
    to_global,
    to_local,
    wheels,
)
from sim.px4.locate import ENV, PX4NotFound, find_px4
from sim.px4.process import GCS_UDP_PORT, PX4Process, claim_instance, lock_held, param_env
from sim.robots import Rover
from sim.world import World
from tests.firmware_helpers import group_gone, px4_or_skip

pytestmark = [pytest.mark.interop, pytest.mark.firmware]

ROOT = Path(__file__).resolve().parents[1]
ORIGIN = Origin()
FIELD = earth_field(ORIGIN.lat, ORIGIN.lon)
TRACK, WHEEL_MAX = 0.58, 2.2  # airframe 1069: RD_WHEEL_TRACK, RO_MAX_THR_SPEED
STILL = RoverState(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def roundtrip(msg):
    """``msg`` packed as MAVLink 2 and parsed back, as PX4 would read it."""
    out = mav.MAVLink(None, srcSystem=1, srcComponent=51)
    return mav.MAVLink(None).parse_buffer(msg.pack(out))[0]


# ----- hil.py: the messages alone -----------------------------------------------------------------------------
def test_at_rest_the_accelerometer_feels_gravity_up_and_the_gyro_nothing():
    m = roundtrip(hil_sensor(STILL, 5000, FIELD, ORIGIN.alt))
    assert m.time_usec == 5000 and m.id == 0
    assert (m.xacc, m.yacc) == (0.0, 0.0) and m.zacc == pytest.approx(-GRAVITY)
    assert (m.xgyro, m.ygyro, m.zgyro) == (0.0, 0.0, 0.0)
    assert m.fields_updated == ALL_SENSORS == ACCEL | GYRO | MAG | BARO and not m.fields_updated & DIFF_PRESS
    # the barometer at the origin's altitude (488 m): the standard atmosphere's pressure and temperature
    assert m.abs_pressure == pytest.approx(956.0, abs=0.5) and m.pressure_alt == pytest.approx(ORIGIN.alt)
    assert m.temperature == pytest.approx(15.0 - 0.0065 * ORIGIN.alt, abs=0.01)
    assert pressure_hpa(0.0) == pytest.approx(1013.25)


def test_moving_the_accelerometer_adds_forward_and_centripetal_force():
    turning = RoverState(0.0, 0.0, 0.0, 1.0, 0.0, 1.5, 0.4, 0.5)  # 1.5 m/s, speeding up, turning right
    m = hil_sensor(turning, 1000, FIELD, ORIGIN.alt)
    assert (m.xacc, m.yacc, m.zacc) == pytest.approx((0.4, 0.75, -GRAVITY))
    assert m.zgyro == 0.5


def test_noise_is_small_centred_and_never_repeats_a_value():
    normal = iter(np.random.default_rng(3).standard_normal(100_000)).__next__
    samples = [hil_sensor(STILL, 1000, FIELD, ORIGIN.alt, noise=SensorNoise(), normal=normal) for _ in range(2000)]
    zacc = np.array([m.zacc for m in samples])
    xmag = np.array([m.xmag for m in samples])
    assert abs(zacc.mean() + GRAVITY) < 0.005 and 0.01 < zacc.std() < 0.03
    assert abs(xmag.mean() - FIELD[0]) < 1e-4
    assert len(set(zacc.tolist())) == len(zacc)  # PX4 drops a sensor that repeats itself ~100 times: STALE


def test_the_field_is_px4s_world_model_at_the_origin():
    n, e, d = FIELD
    strength = math.sqrt(n * n + e * e + d * d)
    # WMM-2020 at Zurich, as PX4's 10-degree tables interpolate it: ~3.4 deg east, ~63 deg down, ~0.48 gauss
    assert math.degrees(math.atan2(e, n)) == pytest.approx(3.4, abs=0.2)
    assert math.degrees(math.atan2(d, math.hypot(n, e))) == pytest.approx(63.2, abs=0.3)
    assert strength == pytest.approx(0.482, abs=0.005)
    with pytest.raises(ValueError, match="outside the magnetic model cell"):
        earth_field(-35.36, 149.17)  # another origin needs its own grid points


@pytest.mark.parametrize("yaw_deg", [0.0, 30.0, 90.0, 180.0, -120.0])
def test_the_magnetometer_turns_with_the_heading(yaw_deg):
    yaw = math.radians(yaw_deg)
    m = hil_sensor(RoverState(0.0, 0.0, yaw, 0.0, 0.0, 0.0, 0.0, 0.0), 1000, FIELD, ORIGIN.alt)
    decl = math.atan2(FIELD[1], FIELD[0])
    heading = math.atan2(-m.ymag, m.xmag) + decl  # what a compass makes of it
    assert math.remainder(heading - yaw, math.tau) == pytest.approx(0.0, abs=1e-6)
    assert math.hypot(m.xmag, m.ymag) == pytest.approx(math.hypot(FIELD[0], FIELD[1]))
    assert m.zmag == pytest.approx(FIELD[2])
    if yaw_deg == 90.0:  # facing east: north is on the left (-y), east ahead (+x)
        assert (m.xmag, m.ymag) == pytest.approx((FIELD[1], -FIELD[0]), abs=1e-6)


def controls(right: float, left: float, armed: bool = True, t: int = 7000):
    c = [right, left] + [0.0] * 14
    mode = mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (mav.MAV_MODE_FLAG_SAFETY_ARMED if armed else 0)
    return roundtrip(mav.MAVLink_hil_actuator_controls_message(t, c, mode, 1))


def test_actuator_controls_are_right_then_left_wheel_and_drive_a_differential_rover():
    w = wheels(controls(0.5, 0.5))
    assert w == Wheels(0.5, 0.5, 7000, True)
    assert rover_command(w, TRACK, WHEEL_MAX) == pytest.approx((1.1, 0.0))  # straight at half of 2.2 m/s
    w = wheels(controls(-0.2, 0.2))  # left forward, right back: turn right on the spot (FRD: positive)
    speed, rate = rover_command(w, TRACK, WHEEL_MAX)
    assert speed == pytest.approx(0.0) and rate == pytest.approx(0.4 * WHEEL_MAX / TRACK) and rate > 0
    # PX4's rover_differential: right = throttle - diff, left = throttle + diff, diff = rate * track / (2 * max)
    throttle, diff = 0.3, 1.0 * TRACK / (2 * WHEEL_MAX)
    speed, rate = rover_command(wheels(controls(throttle - diff, throttle + diff)), TRACK, WHEEL_MAX)
    assert speed == pytest.approx(throttle * WHEEL_MAX) and rate == pytest.approx(1.0)


def test_actuator_controls_clamp_and_disarmed_is_flagged():
    w = wheels(controls(3.0, float("nan"), armed=False))
    assert (w.right, w.left, w.armed) == (1.0, 0.0, False)
    assert wheels(controls(-7.0, -1.0)).right == -1.0


@pytest.mark.parametrize("x, y", [(0.0, 0.0), (3.2, -1.7), (-250.0, 812.5), (1500.0, 1500.0)])
def test_gps_round_trip_to_a_centimetre(x, y):
    s = RoverState(x, y, 0.0, 0.6, -0.8, 1.0, 0.0, 0.0)
    m = roundtrip(hil_gps(s, 123_456, ORIGIN))
    bx, by = gps_position(m, ORIGIN)
    assert bx == pytest.approx(x, abs=0.012) and by == pytest.approx(y, abs=0.012)  # 1e-7 deg is 1.1 cm
    assert m.alt == round(ORIGIN.alt * 1000) and m.fix_type == 3 and m.satellites_visible >= 6
    assert m.eph < 300 and m.epv < 500  # below EKF2's EPH/EPV gates (cm)
    assert (m.vn, m.ve, m.vd, m.vel) == (60, -80, 0, 100)
    assert m.cog == round(math.degrees(math.atan2(-0.8, 0.6)) % 360 * 100)
    assert roundtrip(hil_gps(STILL, 1, ORIGIN)).cog == 65535  # standing still: no course


def test_gps_projects_on_px4s_sphere_so_px4s_local_frame_is_the_scenarios():
    lat, lon = to_global(ORIGIN, 1000.0, 0.0)
    assert math.radians(lat - ORIGIN.lat) * EARTH_RADIUS_M == pytest.approx(1000.0, abs=1e-6) and lon == ORIGIN.lon
    lat, lon = to_global(ORIGIN, -3000.0, 2500.0)  # equidistant: the great-circle distance from the origin is kept
    p0, p1 = math.radians(ORIGIN.lat), math.radians(lat)
    h = math.sin((p1 - p0) / 2) ** 2 + math.cos(p0) * math.cos(p1) * math.sin(math.radians(lon - ORIGIN.lon) / 2) ** 2
    assert 2 * EARTH_RADIUS_M * math.asin(math.sqrt(h)) == pytest.approx(math.hypot(3000.0, 2500.0), abs=1e-6)
    for x, y in ((1000.0, 0.0), (0.0, 1000.0), (-3000.0, 2500.0)):
        assert to_local(ORIGIN, *to_global(ORIGIN, x, y)) == pytest.approx((x, y), abs=1e-6)


def test_gps_is_due_at_ten_hertz_of_px4_time():
    clock = GpsClock()
    due = [t for t in range(1000, 1_001_000, 4000) if clock.due(t)]
    assert due[0] == 1000 and len(due) == 10
    assert all(b - a >= GPS_PERIOD_US for a, b in zip(due, due[1:], strict=False))


# ----- locate.py and process.py without PX4 -----------------------------------------------------------------
def fake_px4(root: Path) -> Path:
    (root / "bin").mkdir(parents=True)
    (root / "etc" / "init.d-posix" / "airframes").mkdir(parents=True)
    (root / "bin" / "px4").write_text("#!/bin/sh\n")
    (root / "bin" / "px4").chmod(0o755)
    (root / "bin" / "px4-param").write_text("px4")  # a symlink flattened into a file, as a copied tree has
    (root / "etc" / "init.d-posix" / "rcS").write_text("")
    (root / "etc" / "init.d-posix" / "airframes" / "1069_hil_rover_differential").write_text("")
    return root


def test_the_option_wins_then_the_environment(tmp_path):
    a, b = fake_px4(tmp_path / "a"), fake_px4(tmp_path / "b")
    assert find_px4(str(a), {ENV: str(b)}) == a.resolve()
    assert find_px4(None, {ENV: str(b)}) == b.resolve()


def test_no_px4_names_both_ways_and_the_readme(tmp_path):
    with pytest.raises(PX4NotFound) as e:
        find_px4(None, {})
    text = str(e.value)
    assert "--px4 DIR" in text and ENV in text and "shared/px4" in text and "README" in text
    with pytest.raises(PX4NotFound, match=f"{ENV}=.*no executable bin/px4"):
        find_px4(None, {ENV: str(tmp_path)})  # given but unusable: an error, never a fallback
    (tmp_path / "c" / "bin").mkdir(parents=True)
    (tmp_path / "c" / "bin" / "px4").write_text("")
    (tmp_path / "c" / "bin" / "px4").chmod(0o755)
    with pytest.raises(PX4NotFound, match="--px4 .*etc/"):
        find_px4(str(tmp_path / "c"), {})


def test_parameters_go_in_as_environment_variables_integers_as_integers():
    env = param_env({"COM_RC_IN_MODE": 4, "COM_DL_LOSS_T": 10.0, "RO_SPEED_P": 0.25})
    assert env == {"PX4_PARAM_COM_RC_IN_MODE": "4", "PX4_PARAM_COM_DL_LOSS_T": "10", "PX4_PARAM_RO_SPEED_P": "0.25"}


def test_the_work_directory_has_its_own_symlinks_and_goes_away(tmp_path):
    src = fake_px4(tmp_path / "px4")
    p = PX4Process(src, 3, {"NAV_DLL_ACT": 1})
    p._lay_out()
    try:
        assert (p.workdir / "bin" / "px4").resolve() == (src / "bin" / "px4").resolve()
        assert os.readlink(p.workdir / "bin" / "px4-param") == "px4"
        env = p.environment()
        assert env["PX4_SIM_MODEL"] == "hil_rover_differential" and env["PX4_PARAM_NAV_DLL_ACT"] == "1"
        assert env["PX4_PARAM_COM_RC_IN_MODE"] == "4"
        assert p.command[1:5] == ["-i", "3", "-w", str(p.workdir / "rootfs")]
    finally:
        p.stop()
    assert not p.workdir.exists()


def test_an_instance_is_claimed_by_its_listening_port_and_never_twice():
    n1, s1 = claim_instance(start=90)
    n2, s2 = claim_instance(start=90)
    try:
        assert n1 != n2
        assert s1.getsockname()[1] == process.SIM_TCP_PORT + n1
    finally:
        s1.close()
        s2.close()


# ----- bridge.py against a stand-in PX4 -----------------------------------------------------------------------
def test_the_bridge_sends_sensors_and_gps_and_returns_the_newest_wheels():
    n, server = claim_instance(start=80)
    bridge = HilBridge(server, noise=None)
    client = socket.create_connection(("127.0.0.1", process.SIM_TCP_PORT + n))
    try:
        bridge.accept(timeout=5)
        w = bridge.step(STILL, 0.004)
        assert w == Wheels(0.0, 0.0, 0, False)  # nothing from PX4 yet
        client.settimeout(2)
        got = []
        parser = mav.MAVLink(None)
        while len(got) < 2:
            got += parser.parse_buffer(client.recv(4096)) or []
        assert [m.get_type() for m in got] == ["HIL_SENSOR", "HIL_GPS"] and got[0].time_usec == 1000
        assert got[0].zacc == pytest.approx(-GRAVITY)
        px4 = mav.MAVLink(None, srcSystem=1, srcComponent=1)
        for t, right in ((1000, 0.1), (1000, 0.3)):
            client.sendall(mav.MAVLink_hil_actuator_controls_message(t, [right, 0.2] + [0.0] * 14, 128, 1).pack(px4))
        deadline = time.monotonic() + 2
        while bridge.answers < 2 and time.monotonic() < deadline:
            w = bridge.step(STILL, 0.004)
        assert (w.right, w.left, w.armed) == (pytest.approx(0.3), pytest.approx(0.2), True)
        assert bridge.time_usec > 5000  # its clock moved on by each step
        client.close()
        with pytest.raises(BridgeError, match="closed|broke"):
            for _ in range(100):
                bridge.step(STILL, 0.004)
                time.sleep(0.001)
    finally:
        client.close()
        bridge.close()


# ----- the real PX4 ----------------------------------------------------------------------------------------------
class Station:
    """A ground station on PX4's GCS link (UDP 18570+i): its first packet makes PX4 answer to this socket instead
    of 14550. It keeps what the test needs (heartbeat, estimator flags, home, acks) and PX4's clock, the newest
    ``time_boot_ms`` it reported: the bridge paces on it while PX4 is disarmed and sends no actuator controls."""

    def __init__(self, instance: int) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)
        self.addr = ("127.0.0.1", GCS_UDP_PORT + instance)
        self.target = instance + 1  # rcS: MAV_SYS_ID = instance + 1
        self.out = mav.MAVLink(None, srcSystem=255, srcComponent=190)
        self.rx = mav.MAVLink(None)
        self.rx.robust_parsing = True
        self.time_usec: int | None = None
        self.heartbeat = None
        self.estimator = 0
        self.home = False
        self.acks: list[tuple[int, int]] = []
        self.texts: list[str] = []

    def send(self, msg) -> None:
        self.sock.sendto(msg.pack(self.out), self.addr)

    def command(self, command: int, *params: float) -> None:
        p = [*params, *[0.0] * (7 - len(params))]
        self.send(mav.MAVLink_command_long_message(self.target, 1, command, 0, *p))

    def velocity(self, t: float, vn: float, ve: float) -> None:
        ignore = 0b110111000111  # position, acceleration, yaw and yaw rate ignored: a velocity target only
        self.send(mav.MAVLink_set_position_target_local_ned_message(
            int(t * 1000), self.target, 1, mav.MAV_FRAME_LOCAL_NED, ignore, 0, 0, 0, vn, ve, 0, 0, 0, 0, 0, 0))

    def poll(self) -> int | None:
        while True:
            try:
                data = self.sock.recv(65536)
            except BlockingIOError:
                return self.time_usec
            for m in self.rx.parse_buffer(data) or ():
                if m.get_srcSystem() != self.target:
                    continue
                boot_ms = getattr(m, "time_boot_ms", None)
                if boot_ms is not None and (self.time_usec is None or boot_ms * 1000 > self.time_usec):
                    self.time_usec = boot_ms * 1000
                kind = m.get_type()
                if kind == "HEARTBEAT" and m.get_srcComponent() == 1:
                    self.heartbeat = m
                elif kind == "ESTIMATOR_STATUS":
                    self.estimator = m.flags
                elif kind == "HOME_POSITION":
                    self.home = True
                elif kind == "COMMAND_ACK":
                    self.acks.append((m.command, m.result))
                elif kind == "STATUSTEXT":
                    self.texts.append(m.text)

    @property
    def armed(self) -> bool:
        return bool(self.heartbeat and self.heartbeat.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED)

    @property
    def main_mode(self) -> int | None:
        return None if self.heartbeat is None else (self.heartbeat.custom_mode >> 16) & 0xFF


PX4_OFFBOARD = 6  # PX4's main mode number
DT = 0.004  # 250 Hz: the IMU rate PX4's SITL expects (IMU_INTEG_RATE)


def test_stop_ends_a_px4_that_waits_for_its_simulator():
    """While nothing accepts its simulator link the PX4 server ignores SIGTERM (it waits on its start-up script,
    which waits on the px4-simulator_mavlink client): stopping the whole group still leaves nothing running."""
    px4_dir = px4_or_skip()
    n, server = claim_instance()
    server.close()  # nobody listens: PX4 retries its connection, waiting
    p = PX4Process(px4_dir, n).start()
    try:
        deadline = time.monotonic() + 20
        while "Waiting for simulator" not in p.log_text() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert "Waiting for simulator" in p.log_text(), p.log_tail()
        assert lock_held(n)
        os.kill(p.pid, signal.SIGTERM)  # the server alone: it stays
        time.sleep(0.5)
        assert p.alive()
    finally:
        started = time.monotonic()
        status = p.stop()
    assert status is not None and group_gone(p.pid) and not lock_held(n) and not p.workdir.exists()
    assert time.monotonic() - started < 5.0


def test_px4_drives_the_rover_north_in_offboard_in_lockstep(capsys):
    px4_dir = px4_or_skip()
    n, server = claim_instance()
    station = Station(n)
    bridge = HilBridge(server, ORIGIN, clock=station.poll, watch=[station.sock])
    world = World(())
    rover = Rover(world, 0.0, 0.0, 0.3, np.random.default_rng(1))  # facing a little east of north
    p = PX4Process(px4_dir, n).start()

    def state() -> RoverState:
        x, y, yaw = rover.pose
        v = rover.body.velocity
        return RoverState(x, y, yaw, v.x, v.y, rover.true_speed, rover.accel, rover.body.angular_velocity)

    def sim_t() -> float:
        return bridge.time_usec / 1e6

    next_heartbeat = 0.0

    def step() -> None:
        """One physics step in lockstep, and the station's 1 Hz heartbeat (PX4's GCS link needs one)."""
        nonlocal next_heartbeat
        w = bridge.step(state(), DT)
        rover.command(*rover_command(w, TRACK, WHEEL_MAX))
        rover.before_step(DT)
        world.step(DT)
        rover.after_step(DT)
        station.poll()
        if sim_t() >= next_heartbeat:
            next_heartbeat += 1.0
            station.send(mav.MAVLink_heartbeat_message(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3))

    def until(done, limit_s: float, what: str, setpoints: bool = False) -> None:
        end = sim_t() + limit_s
        next_sp = sim_t()
        while not done():
            step()
            if setpoints and sim_t() >= next_sp:  # 10 Hz, well above Offboard's 2 Hz minimum
                next_sp += 0.1
                station.velocity(sim_t(), 1.0, 0.0)
            assert sim_t() < end, f"{what}: not within {limit_s:g} simulated s; PX4 said {station.texts[-5:]}\n" \
                                  f"{p.log_tail()}"

    try:
        bridge.accept(alive=p.alive)
        assert lock_held(n)
        wall0 = time.perf_counter()
        pos_flags = mav.ESTIMATOR_POS_HORIZ_ABS | mav.ESTIMATOR_POS_HORIZ_REL
        until(lambda: station.home and station.estimator & pos_flags == pos_flags, 60.0, "EKF2 position")
        boot_s = sim_t()
        until(lambda: sim_t() > boot_s + 1.0, 2.0, "setpoint stream", setpoints=True)
        station.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1)
        until(lambda: station.armed, 5.0, "arming", setpoints=True)
        station.command(mav.MAV_CMD_DO_SET_MODE, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, PX4_OFFBOARD)
        until(lambda: station.main_mode == PX4_OFFBOARD, 5.0, "Offboard", setpoints=True)
        x0, y0, _ = rover.pose
        t0, wall_drive = sim_t(), time.perf_counter()
        until(lambda: sim_t() > t0 + 6.0, 7.0, "driving", setpoints=True)
        x1, y1, yaw1 = rover.pose
        drive_wall = time.perf_counter() - wall_drive
        station.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 0)
        until(lambda: not station.armed, 5.0, "disarming")
        wall = time.perf_counter() - wall0
    finally:
        status = p.stop()  # first, while the bridge still holds the instance's port
        bridge.close()
    north, east = x1 - x0, y1 - y0
    with capsys.disabled():
        print(f"\nPX4 lockstep: EKF2 position at {boot_s:.1f} simulated s; drove {north:.2f} m north, {east:+.2f} m "
              f"east in 6 s; real-time factor {sim_t() / wall:.1f}x overall ({sim_t():.1f} simulated s in "
              f"{wall:.2f} wall s), {6.0 / drive_wall:.1f}x while driving; {bridge.answers} actuator answers, "
              f"{bridge.waits} waits ({bridge.waited_s:.2f} s), {bridge.free_s:.2f} s at the free pace")
    assert (mav.MAV_CMD_COMPONENT_ARM_DISARM, mav.MAV_RESULT_ACCEPTED) in station.acks
    assert north >= 3.0 and abs(east) < 0.5 and abs(math.remainder(yaw1, math.tau)) < 0.1
    # "about 1 m/s": the last 6 s include the start from rest (RO_ACCEL_LIM) and the controller settling
    assert 0.8 <= north / 6.0 <= 1.1 and rover.true_speed == pytest.approx(0.0, abs=0.05)
    assert status is not None and group_gone(p.pid) and not lock_held(n) and not p.workdir.exists()
