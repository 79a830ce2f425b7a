"""The vehicle loop's shell with an injected clock and link: paced ticks, frames both ways, no wall clock."""

from __future__ import annotations

import numpy as np

from sim.driver import SimDriver
from sim.scenario import load
from vehicle.app import DT, Vehicle, run
from vehicle.endpoint import Endpoint
from vehicle.estimator import Pose
from vehicle.params import load_defaults
from vehicle.services.base import mav


def test_run_paces_ticks_by_the_injected_clock_and_moves_frames():
    sc = load("open")
    driver = SimDriver(sc, "rover", np.random.default_rng(1))
    vehicle = Vehicle(driver, load_defaults(), sc.start, 0.0, seed=1)
    endpoint = Endpoint(vehicle)
    now = [100.0]
    slept: list[float] = []
    sent: list[tuple[bytes, float]] = []
    hb = mav.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3).pack(mav.MAVLink(None, 255, 190))

    def sleep(s: float) -> None:
        slept.append(s)
        now[0] += s

    run(vehicle, endpoint, receive=lambda t: [hb] if abs(t - 0.5) < 1e-9 else [],
        send=lambda frame, t: sent.append((frame, t)), clock=lambda: now[0], sleep=sleep, speedup=2.0,
        stop=lambda: vehicle.t >= 1.0 - 1e-9, after_tick=lambda t: driver.advance(DT))
    assert abs(vehicle.t - 1.0) < 1e-9
    assert len(slept) == 50 and all(abs(s - DT / 2) < 1e-9 for s in slept)  # twice real time
    assert abs(now[0] - 100.5) < 1e-9
    kinds = [endpoint.parser.parse_buffer(f)[0].get_type() for f, _ in sent]
    assert kinds.count("HEARTBEAT") == 1 and "LEASE_STATUS" in kinds
    assert vehicle.book.link.last_heard is None  # a heartbeat alone gives no one the vehicle


def test_run_answers_a_command_that_arrives_between_ticks_before_the_next_tick():
    """With ``wait`` the link is served between ticks: a COMMAND_LONG arriving 5 ms after a tick is answered at once,
    at that tick's time, with nothing else sent and the vehicle not stepped (simulated clock only)."""
    sc = load("open")
    driver = SimDriver(sc, "rover", np.random.default_rng(1))
    vehicle = Vehicle(driver, load_defaults(), sc.start, 0.0, seed=1)
    endpoint = Endpoint(vehicle)
    gcs = mav.MAVLink(None, 255, 190)
    cmd = gcs.command_long_encode(1, 1, mav.MAV_CMD_REQUEST_MESSAGE, 0, mav.MAVLINK_MSG_ID_HOME_POSITION,
                                  0, 0, 0, 0, 0, 0).pack(gcs)
    now = [100.0]
    inbox: list[bytes] = []
    sent: list[tuple[str, float, float, float]] = []  # (type, send t, clock, vehicle time)
    ticks: list[float] = []  # clock at each tick's start

    def wait(timeout: float) -> bool:
        if abs(vehicle.t - 0.5) < 1e-9 and not any(k == "COMMAND_ACK" for k, *_ in sent):
            now[0] += 0.005  # the command comes in 5 ms after the tick
            inbox.append(cmd)
            return True
        now[0] += timeout
        return False

    def receive(t: float) -> list[bytes]:
        ticks.append(now[0])
        out = list(inbox)
        inbox.clear()
        return out

    def send(frame: bytes, t: float) -> None:
        sent.append((endpoint.parser.parse_buffer(frame)[0].get_type(), t, now[0], vehicle.t))

    run(vehicle, endpoint, receive=receive, send=send, clock=lambda: now[0], sleep=lambda s: None,
        stop=lambda: vehicle.t >= 1.0 - 1e-9, after_tick=lambda t: driver.advance(DT), wait=wait)
    (ack,) = [s for s in sent if s[0] == "COMMAND_ACK"]
    _, t_sent, clock_sent, vehicle_t = ack
    assert abs(t_sent - 0.5) < 1e-9 and abs(vehicle_t - 0.5) < 1e-9  # at the tick's time, the vehicle not stepped
    next_tick = min(c for c in ticks if c > clock_sent)
    assert clock_sent < next_tick and abs(clock_sent - (100.0 + 0.5 - DT + 0.005)) < 1e-9  # 5 ms after the tick
    between = [k for k, _, c, _ in sent if abs(c - clock_sent) < 1e-12]
    assert sorted(between) == ["COMMAND_ACK", "HOME_POSITION"]  # the answers only: telemetry stays on the tick
    assert abs(vehicle.t - 1.0) < 1e-9 and abs(now[0] - 101.0) < 1e-9  # and the pacing is unchanged


def test_the_pose_of_a_tick_is_a_whole_value():
    """The estimator makes its pose with the named tuple's ``_make`` (every field in order): it must be the same
    value as the named tuple's own constructor gives, every field present."""
    sc = load("tunnel")
    driver = SimDriver(sc, "rover", np.random.default_rng(1))
    vehicle = Vehicle(driver, load_defaults(), sc.start, 0.0, seed=1)
    t = 0.0
    for _ in range(5):
        t = round(t + DT, 9)
        vehicle.tick(t)
    p = vehicle.estimator.pose
    assert type(p) is Pose and len(p) == len(Pose._fields) and p == Pose(p.x, p.y, p.yaw, p.std, p.t)
