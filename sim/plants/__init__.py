"""What flies a scenario, behind one port: the ``Plant`` the one simulator loop (``sim.runner.Run``) drives.

A scenario is flown by one of five plants: ``native`` (returnlink's vehicle on a pymunk robot), ``firmware`` (the
real ArduPilot Rover firmware over its JSON physics backend, its own failsafes), ``companion`` (that firmware with
returnlink companion on its telemetry port), ``applet`` (that firmware carrying returnlink's Lua applet) and ``px4``
(the real PX4 rover over its HIL simulator link, its own data-link failsafe). Everything around the plant is the
loop's, once for all five: simulated time, the radio model and its lockstep bus, the scripted ground stations, the
scenario's timed events and jams, RADIO_STATUS, the per-tick record, the .tlog, the progress bar; and after the run
one metrics pipeline, one verdict (``sim.metrics``). So a plant is compared with another in the very same world,
packet fates and operator script, as ArduPilot's SITL flies many physics backends behind one packet contract.

The same plants fly in real time (``sim.serve.Server``, `sim serve`): the lockstep loop's tick paced to the wall
clock, with ground stations of one's own behind the radio proxy instead of the scripted ones.

The loops never reach into a plant beyond this protocol, and a plant never imports a loop: it is handed what it
needs (the scenario, the seed, the frames the radio delivered) and answers in plain values.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from pathlib import Path
from typing import Any, Protocol

from link.radio import LinkState
from sim.compare import Repeatability
from sim.robots import Robot
from sim.scenario import Event, Station
from sim.world import World
from vehicle.core import Core


class Plant(Protocol):
    """What the loop needs of whatever flies the scenario (see the module docstring).

    One tick of the loop, in order: the stations hear what the radio delivered to them -> timed events -> the
    scripted operators decide -> [the plant hears what the radio delivered to the vehicle (``receive``) and ticks
    (``tick``)] -> the true pose (``robot``) sets every station's channel -> the plant's frames to the ground
    (``frames``) go out through the radio -> the stations send theirs -> RADIO_STATUS (``radio_status``) -> the
    record (``record``, ``estimate``). The bracketed step comes before the ground's radio leg, or after
    it when ``hears_last`` (see there)."""

    kind: str  # the vehicle as metrics.json names it (rover, legged, ardurover, px4rover)
    world: World  # walls, attenuation and the collision count: the radio and the record read it
    robot: Robot  # its pose is the truth: the radio model's position, the record's true path
    frame_offset: tuple[float, float]  # where the vehicle's own frame (its trail, its link map) lies in the true one
    # whether returnlink's lease machinery flies (its vehicle, or the companion's): the loop then keeps the lease
    # record (blocks, losses, regains) and the per-tick trace of it, and the verdict judges the lease criteria
    leases: bool
    # when the vehicle hears and ticks in the loop's tick: False, before the stations' radio leg (the native robot,
    # whose physics steps within its tick, so the radio carries the frames of the pose just reached); True, after it
    # (the firmware, whose physics steps between the loop's ticks while it waits for its answers: what the radio
    # delivered by now reaches it before its next frame)
    hears_last: bool
    rows: list[tuple] | None  # the plant's own per-tick rows (t, true x, true y, est x, est y, ...), or None
    stale: int  # actuations its own audit found outside the lease (the companion's router: frames it forwarded)
    repeatability: Repeatability  # how far two runs of one trial may differ (``sim.compare``; exact for a native one)
    contingency: Any  # the link-loss baseline (``sim.policies``) its vehicle flies instead of the return plan, or None

    @property
    def vehicle(self) -> Core | None:
        """returnlink's vehicle aboard, whose leases the run records; None: none (or not booted yet)."""

    # ----- the scenario around it ----------------------------------------------------------------------------
    def station(self, spec: Station, operator: bool) -> tuple[Any, Any]:
        """The software of one scenario station, as this plant is flown: (what it hears and sends, anything with
        ``feed(data, t)`` and ``tick(t) -> frames``, or None for a station nobody runs; the scripted operator,
        anything with ``step(t)``, or None). ``operator``: the scenario's operator station."""

    def event(self, ev: Event, station: Any, t: float) -> str | None:
        """What a timed event does to the stations' software (after the loop applied its radio part, if any:
        ``sim.jams``); a note for the report when it does not apply to this plant."""

    # ----- time ----------------------------------------------------------------------------------------------
    def start(self) -> None:
        """Bring the plant to scenario time 0 (the firmware: start its process and let it boot)."""

    def pace(self, tick: Callable[[float], bool], duration: float) -> None:
        """Move simulated time on to ``duration``, calling ``tick(t)`` at every 20 ms of it until it answers False."""

    def close(self) -> None:
        """Stop whatever runs outside this process (always called, in a ``finally``)."""

    # ----- one tick ------------------------------------------------------------------------------------------
    def frames(self, t: float) -> list[bytes]:
        """What the vehicle's radio sends to the ground this tick."""

    def receive(self, frames: list[tuple[bytes, Hashable]], t: float) -> None:
        """What the radio delivered to the vehicle by ``t``: (bytes, where from: the sending station's name, or its
        UDP address when served) in arrival order."""

    def replies(self) -> list[bytes]:
        """The answers to what was received since the last tick, without a tick: what a real-time loop serving its
        link between ticks sends at once (docs/architecture.md §8)."""

    def pinned(self) -> list[Hashable]:
        """The addresses a real-time transport must never drop from its peer table (the owner's)."""

    def tick(self, t: float) -> None:
        """The vehicle's own tick (and, for a plant without a clock of its own, the physics step after it)."""

    def radio_status(self, state: LinkState, t: float) -> None:
        """Once a second, the vehicle-side telemetry radio's report of the operator station's channel."""

    # ----- the record ----------------------------------------------------------------------------------------
    def estimate(self) -> tuple[float, float]:
        """Where the plant believes it is, in the true frame (NaN while it has no estimate). The loop reads a
        returnlink vehicle's own estimator where there is one (``vehicle``, through ``frame_offset``)."""

    def record(self, t: float, pos: tuple[float, float], link: float, rssi: float) -> None:
        """The plant's own row of the tick (``rows``; not called when that is None), given the true position and
        the operator's channel."""

    def status(self) -> str:
        """What the progress line (and a served run's status line) says of the plant besides the time."""

    def started(self) -> str:
        """What a served run says once ``start`` has returned (the autopilot's version and boot time), or ""."""

    # ----- the figures ---------------------------------------------------------------------------------------
    def figures(self, run: Any) -> dict:
        """The §7 figures only the plant's own record can give (``sim.metrics.compute`` adds the rest)."""

    def summary(self, run: Any, m: dict) -> str:
        """The printed summary of a run and its metrics."""

    def pictures(self, run: Any, out: Path) -> list[Path]:
        """trajectory.png and timeline.png of a run in ``out``, as this plant's record draws them (its drawing module
        imported only now: matplotlib is slow to import)."""


__all__ = ["Plant"]
