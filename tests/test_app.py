"""The vehicle loop's shell with an injected clock and link: paced ticks, frames both ways, no wall clock."""

from __future__ import annotations

import numpy as np

from sim.driver import SimDriver
from sim.scenario import load
from vehicle.app import DT, Vehicle, run
from vehicle.mavlink import Endpoint, mav
from vehicle.params import load_defaults


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
