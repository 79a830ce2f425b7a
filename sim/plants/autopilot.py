"""What the plants of the real autopilots share: the ArduPilot firmware (``sim.plants.firmware``) and PX4
(``sim.plants.px4``), each a separate process driving the scenario's pymunk rover in lockstep, its MAVLink link the
vehicle's side of the radio.

Both are paced by their lockstep (the physics steps while the autopilot waits for its answers, so the loop's tick
comes from the physics' own time), hear what the radio delivered before their next step (``hears_last``), have no
returnlink aboard (no leases, nothing to audit), keep their record as rows of their own, and are judged from their
mode timeline (``sim.firmware.metrics``, ``sim.firmware.report``, which read the modes' meaning from the plant).
What differs is said by the subclass: its name, its lockstep's clock, its estimate and its modes' names.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from link.radio import LinkState, subsystem_rng
from sim.firmware import metrics
from sim.jams import RADIO_EVENTS
from sim.robots import make_robot
from sim.scenario import Event, Scenario
from sim.summary import summary

DT = 0.02  # the loop's tick (sim.plants.native.TICK_RATE): what moves around the autopilot moves at this pace


class AutopilotPlant:
    """The shared half of an autopilot's plant (see the module docstring). A subclass sets ``link`` (its lockstep:
    ``tap``, ``cmd``, ``boot_s``, ``frames``, ``drain``, ``send``, ``close``), ``world``, ``rows``, ``heard`` and
    ``_op_name``, and says the four things below that differ."""

    autopilot = "the autopilot"  # its name in notes and pictures
    hears_last = True
    leases = False
    vehicle = None  # no returnlink aboard
    stale = 0  # no lease to audit against
    repeatability = metrics.REPEATABILITY  # within the autopilot's own determinism (its threads, its timing)
    contingency = None  # no returnlink aboard, so no baseline flown in its place

    kind: str
    policies: tuple[str, ...]

    def _set_scene(self, scenario: Scenario, kind: str, seed: int | None, policy: str, binary, what: str) -> None:
        """What every autopilot's plant starts from: the vehicle, policy and binary checked (``what`` names the
        binary in the error), the scenario's world and its pymunk rover at the start, the autopilot's local frame
        (its EKF origin, the start) in the true frame, and an empty record."""
        if kind != self.kind:
            raise ValueError(f"vehicle {kind!r} is not {self.autopilot} ({self.kind!r})")
        if policy not in self.policies:
            raise ValueError(f"policy {policy!r} is not one of {', '.join(self.policies)}")
        if binary is None:
            raise ValueError(f"no {what} given")
        self.scenario = sc = scenario
        self.policy = policy
        self.seed = sc.seed if seed is None else seed
        self.world = sc.world()
        x, y, yaw = sc.start
        self.robot = make_robot("rover", self.world, x, y, yaw, subsystem_rng(self.seed, "robot"))
        self.origin = (x, y)
        self.frame_offset = self.origin
        self.lnk_timeout = float(sc.params.get("LNK_TIMEOUT", 3.0))
        self.rows: list[tuple] = []
        self.heard: list[float] = []
        self.operator = None  # made with the operator's station
        self._op_name = sc.operator_station

    # ----- what differs ------------------------------------------------------------------------------------------
    def _physics_time(self) -> float:
        """The lockstep's physics time, on which the autopilot's own clock runs."""
        raise NotImplementedError

    def _connected(self) -> bool:
        """Whether what is sent reaches the autopilot now (the ArduPilot firmware's address is known only once it
        has spoken)."""
        return True

    def _autopilot_estimate(self) -> tuple[float, float]:
        """The autopilot's own position estimate in the true frame (nan, nan: none yet)."""
        raise NotImplementedError

    def _mode_name(self, mode: int) -> str:
        """The autopilot's name of a mode number."""
        raise NotImplementedError

    # ----- the scenario around it ----------------------------------------------------------------------------
    def event(self, ev: Event, st, t: float) -> str | None:
        """The operator asks for the autopilot's return when the scenario says so; leases, claims and returnlink
        parameters mean nothing to it: said, not faked."""
        if ev.action in RADIO_EVENTS:
            return None
        if ev.action == "rtl" and st is not None and st.gs is not None:
            st.gs.request_rtl(t)
            return None
        return f"t={ev.t:g} s: event {ev.action!r} does not apply to {self.autopilot}"

    # ----- time ----------------------------------------------------------------------------------------------
    def start(self) -> None:
        """Start the autopilot's process and boot it to its first estimate on the simulator's clock."""
        self.link.start()
        self.link.boot()

    def pace(self, tick: Callable[[float], bool], duration: float) -> None:
        """The physics' time, step by step, with a tick each time it crosses a multiple of DT after the boot
        (scenario time 0)."""
        boot = self.link.boot_s
        last, going = 0.0, True

        def at_tick(t_phys: float) -> None:
            nonlocal last, going
            if not going:
                return
            t = round(t_phys - boot, 9)
            if t <= 0:
                return
            last = t
            going = tick(t)

        while going and last < duration - 1e-9:
            self.link.frames(self._physics_time() + DT, at_tick)

    def close(self) -> None:
        self.link.close()
        if self.link.tap.version is None:
            self.link.tap.version = f"{self.autopilot} (version not reported)"

    # ----- one tick: the vehicle's side of the radio is the autopilot's MAVLink link itself ---------------------
    def frames(self, t: float) -> list[bytes]:
        """Everything the autopilot said since the last tick."""
        return self.link.drain(t)

    def receive(self, frames: list[tuple[bytes, str]], t: float) -> None:
        """Straight to the autopilot, before its next physics step."""
        for data, src in frames:
            if self._connected():
                self.link.send(data)
                if src == self._op_name:
                    self.heard.append(t)

    def tick(self, t: float) -> None:
        """Nothing beside the autopilot, which runs its own loops between the ticks."""

    def radio_status(self, state: LinkState, t: float) -> None:
        """The autopilot reads no RADIO_STATUS of its own link here: its failsafe hears the radio's frames."""

    def replies(self) -> list[bytes]:
        """Nothing between ticks: what was received went to the autopilot at once, which answers in its own time
        (its frames leave with the next tick's)."""
        return []

    def pinned(self) -> list:
        """No address to keep: the autopilot keeps its own ground stations."""
        return []

    # ----- the record ----------------------------------------------------------------------------------------
    def estimate(self) -> tuple[float, float]:
        return self._autopilot_estimate()

    def record(self, t: float, pos: tuple[float, float], link: float, rssi: float) -> None:
        ex, ey = self._autopilot_estimate()
        tap = self.link.tap
        mode = -1 if tap.mode is None else tap.mode
        self.rows.append((t, pos[0], pos[1], ex, ey, mode, link, rssi, *self.link.cmd, tap.armed,
                          self.world.collisions))

    def status(self) -> str:
        """The autopilot's mode and whether it is armed."""
        tap = self.link.tap
        mode = "?" if tap.mode is None else self._mode_name(tap.mode)
        return f"  {mode:<12} {'armed' if tap.armed else 'disarmed'}"

    def started(self) -> str:
        """The autopilot's version and how long it took to boot."""
        return f"{self.link.tap.version or self.autopilot} ready after {self.link.boot_s:.1f} simulated s"

    # ----- the figures ---------------------------------------------------------------------------------------
    @property
    def firmware_modes(self) -> list[dict]:
        """Its mode timeline as the autopilot names its modes (metrics.json's ``firmware_modes``)."""
        return [{"t": round(t, 3), "mode": self._mode_name(m)} for t, m in self.link.tap.modes]

    def figures(self, run) -> dict:
        return metrics.figures(run)

    def summary(self, run, m: dict) -> str:
        """The one summary, with the autopilot's version and boot under its first line."""
        return summary(run, m, [f"  firmware {m['firmware']} (booted in {self.link.boot_s:.1f} simulated s before "
                                "scenario time 0)"])

    @staticmethod
    def pictures(run, out: Path) -> list[Path]:
        """trajectory.png (every run's, ``sim.report``) and timeline.png of the modes (``sim.firmware.report``);
        matplotlib is imported only when plots are drawn (about 0.4 CPU-s)."""
        from sim import report
        from sim.firmware import report as modes_report

        return [report.trajectory(run, out / "trajectory.png"), modes_report.timeline(run, out / "timeline.png")]


__all__ = ["DT", "AutopilotPlant"]
