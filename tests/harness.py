"""A vehicle and ground stations wired back to back in simulated time, with a perfect link."""

from __future__ import annotations

import numpy as np

from gcs.station import GroundStation
from link.signing import Key
from sim.driver import SimDriver
from sim.scenario import load
from vehicle.app import DT, Vehicle
from vehicle.endpoint import Endpoint
from vehicle.params import load_defaults


class Pair:
    def __init__(self, scenario: str = "open", vehicle: str = "rover", seed: int = 1, stations=(255,),
                 vehicle_key: Key | None = None, keys: dict[int, Key] | None = None, intruders=(),
                 **endpoint_options) -> None:
        """``vehicle_key`` installs a signing key on the vehicle, ``keys`` gives stations theirs; ``intruders`` are
        extra stations without a key, by sysid (they may share a sysid with a station: spoofing)."""
        sc = load(scenario)
        self.driver = SimDriver(sc, vehicle, np.random.default_rng(seed))
        self.vehicle = Vehicle(self.driver, load_defaults(), sc.start, 0.0, seed=seed)
        self.endpoint = Endpoint(self.vehicle, key=vehicle_key, **endpoint_options)
        keys = keys or {}
        self.stations = {s: GroundStation(s, 190, key=keys.get(s)) for s in stations}
        self.intruders = [GroundStation(s, 190) for s in intruders]
        self.t = 0.0
        self.raw: list[bytes] = []  # extra bytes to inject into the vehicle next tick
        self.heard: list[bytes] = []  # every frame the vehicle sent
        # whether a station's next frame to the vehicle is lost (a radio outage): (sysid, t) -> lost
        self.lose = lambda sysid, t: False

    @property
    def gs(self) -> GroundStation:
        return next(iter(self.stations.values()))

    def step(self, seconds: float = DT) -> None:
        for _ in range(max(1, int(round(seconds / DT)))):
            self.t = round(self.t + DT, 9)
            for gs in [*self.stations.values(), *self.intruders]:
                sysid = gs.sysid
                for frame in gs.tick(self.t):
                    if not self.lose(sysid, self.t):
                        self.endpoint.receive(frame, self.t)
            for data in self.raw:
                self.endpoint.receive(data, self.t)
            self.raw.clear()
            self.vehicle.tick(self.t)
            self.driver.advance(DT)
            for frame in self.endpoint.tick(self.t):
                self.heard.append(frame)
                for gs in [*self.stations.values(), *self.intruders]:
                    gs.feed(frame, self.t)

    def until(self, predicate, seconds: float, what: str) -> None:
        end = self.t + seconds
        while not predicate():
            assert self.t < end, f"no {what} within {seconds} simulated s"
            self.step()

    def connect(self) -> None:
        self.until(lambda: self.gs.vehicle.status is not None, 3, "LEASE_STATUS")

    def take_control(self, plan: str | None = None, arm: bool = True) -> Pair:
        """Connect, acquire the root with the first station, upload ``plan`` (a gcs plan spec) if given and arm;
        every answer must be a success."""
        from gcs.plans import parse_spec

        self.connect()
        p = self.gs.acquire()
        tr = self.gs.upload(parse_spec(plan)) if plan is not None else None
        self.until(lambda: p.done and (tr is None or tr.done), 3, "acquire and upload")
        assert p.ok and (tr is None or tr.ok), "could not take control"
        if arm:
            a = self.gs.arm()
            self.until(lambda: a.done, 2, "arm ACK")
            assert a.ok, "arm refused"
        return self
