"""`sim serve`'s one real-time loop (``sim.serve.Server``) with a plant plugged in: a stand-in plant of a few lines,
no firmware, no socket traffic. The loop keeps the lockstep loop's tick order whatever the plant (``hears_last``),
hands a plant what the ground sent with the address it came from, reports the radio once a second, and holds
simulated time to the wall clock (injected clocks: simulated time only)."""

from __future__ import annotations

import pytest

from sim.scenario import load
from sim.serve import Server, WallPace

GROUND = ("127.0.0.1", 14550)


class _Robot:
    pose = (1.0, 2.0, 0.0)


class _StandIn:
    """A plant that flies nothing: it logs what the loop asks of it, says one frame a tick, and answers at once."""

    kind = "stand-in"
    leases = False
    hears_last = False
    rows = None
    stale = 0
    vehicle = None
    frame_offset = (0.0, 0.0)

    def __init__(self, scenario, kind, seed, policy, ticks: int = 5) -> None:
        self.world = scenario.world()
        self.robot = _Robot()
        self.ticks = ticks
        self.calls: list[tuple] = []

    def start(self) -> None:
        self.calls.append(("start",))

    def pace(self, tick, duration) -> None:
        for k in range(1, self.ticks + 1):
            if not tick(k / 50):
                return

    def close(self) -> None:
        self.calls.append(("close",))

    def receive(self, frames, t) -> None:
        self.calls.append(("receive", t, tuple(frames)))

    def tick(self, t) -> None:
        self.calls.append(("tick", t))

    def frames(self, t) -> list[bytes]:
        self.calls.append(("frames", t))
        return [b"down %g" % t]

    def replies(self) -> list[bytes]:
        return [b"answer"]

    def pinned(self) -> list:
        return []

    def radio_status(self, state, t) -> None:
        self.calls.append(("radio", t))

    def estimate(self) -> tuple[float, float]:
        return 1.5, 2.5

    def status(self) -> str:
        return "  standing in"

    def started(self) -> str:
        return "stand-in ready"


class _HearsLast(_StandIn):
    hears_last = True


class _Ground:
    """The server's UDP side in memory: one datagram from the ground waiting at every read, every one sent kept."""

    def __init__(self) -> None:
        self.sent: list[bytes] = []
        self.reads = 0

    def receive(self, max_packets: int = 256) -> list[tuple[bytes, tuple[str, int]]]:
        self.reads += 1
        return [(b"up %d" % self.reads, GROUND)]

    def send(self, data: bytes, to=None) -> None:
        self.sent.append(data)


def _served(plant: type, **serve) -> tuple[Server, _Ground]:
    server = Server(load("open"), port=0, peers=(), perfect_link=True, plant=plant)
    ground = _Ground()
    server.proxy.transport = ground
    now = [0.0]
    try:
        server.serve(clock=lambda: now[0], sleep=lambda s: now.__setitem__(0, now[0] + s), out=None, **serve)
    finally:
        server.close()
    return server, ground


def _order(calls: list[tuple], t: float) -> list[str]:
    return [c[0] for c in calls if len(c) > 1 and c[1] == t and c[0] != "radio"]


@pytest.mark.parametrize(("plant", "order"), [(_StandIn, ["receive", "tick", "frames"]),
                                              (_HearsLast, ["frames", "receive", "tick"])])
def test_a_plant_hears_and_ticks_where_the_lockstep_loop_has_it(plant, order):
    server, ground = _served(plant)
    calls = server.plant.calls
    assert calls[0] == ("start",) and calls[-1] == ("close",)
    for k in range(1, 6):
        assert _order(calls, k / 50) == order
    assert ground.sent == [b"down %g" % (k / 50) for k in range(1, 6)]  # each tick's frames left in that tick


def test_what_the_ground_sent_reaches_the_plant_with_its_address():
    server, _ = _served(_StandIn)
    received = [c[2] for c in server.plant.calls if c[0] == "receive"]
    assert received[0] == ((b"up 1", GROUND),)


def test_the_vehicle_side_radio_reports_once_a_simulated_second():
    class Long(_StandIn):
        def __init__(self, *a) -> None:
            super().__init__(*a, ticks=160)

    server = Server(load("open"), port=0, peers=(), perfect_link=False, plant=Long)
    now = [0.0]
    try:
        server.serve(clock=lambda: now[0], sleep=lambda s: now.__setitem__(0, now[0] + s), out=None)
    finally:
        server.close()
    assert [c[1] for c in server.plant.calls if c[0] == "radio"] == pytest.approx([0.02, 1.02, 2.02, 3.02])


def test_answers_between_ticks_leave_at_once():
    """Input ready while the loop waits for the wall clock is handed to the plant, and its replies leave then."""
    server = Server(load("open"), port=0, peers=(), perfect_link=True, plant=_StandIn)
    ground = _Ground()
    server.proxy.transport = ground
    now = [0.0]

    def wait(timeout: float) -> bool:  # input is ready half-way to the next tick, once per tick
        if now[0] % 0.02 < 0.005:
            now[0] += 0.01
            return True
        now[0] += timeout
        return False

    try:
        server.serve(clock=lambda: now[0], sleep=lambda s: now.__setitem__(0, now[0] + s), out=None, wait=wait)
    finally:
        server.close()
    assert b"answer" in ground.sent
    between = [c for c in server.plant.calls if c[0] == "receive"]
    assert len(between) > 5  # each tick's own, and the ones between ticks


def test_the_wall_clock_holds_each_tick_to_its_moment_and_never_runs_ahead():
    now = [100.0]
    slept: list[float] = []

    def sleep(s: float) -> None:
        slept.append(s)
        now[0] += s

    pace = WallPace(2.0, lambda: now[0], sleep, None)
    pace.mark(0.02)
    pace.hold(0.02, lambda: None)  # the first tick is where time starts: no wait
    now[0] += 0.004  # the next tick took 4 ms
    pace.hold(0.04, lambda: None)
    assert slept == [pytest.approx(0.006)] and now[0] == pytest.approx(100.01)  # 20 ms simulated = 10 ms wall
    now[0] += 1.0  # a machine too slow: behind, so no wait
    pace.hold(0.06, lambda: None)
    assert len(slept) == 1


@pytest.mark.parametrize("speedup", [0.0, -1.0, float("inf"), float("nan")])
def test_a_pace_that_is_no_pace_is_refused(speedup):
    with pytest.raises(ValueError, match="speedup"):
        WallPace(speedup, lambda: 0.0, lambda s: None, None)
