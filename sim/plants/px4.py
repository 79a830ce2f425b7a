"""The PX4 plant: the real PX4 rover in a scenario's world, flying its own data-link failsafe, for
``sim.runner.Run`` (``returnlink sim run SCENARIO --vehicle px4rover --policy px4-hold|px4-return``;
docs/architecture.md §10.1).

The scenario's pymunk rover (walls stay collisions) is driven by PX4's wheel outputs (HIL_ACTUATOR_CONTROLS of
airframe 1069) through the HIL bridge, in lockstep on HIL_SENSOR time (``sim.px4.lockstep``): the physics steps at
250 Hz, PX4's clock follows the sensor stream, so simulated time is the physics' own and the run goes as fast as
both processes allow. Every 20 ms of it the loop's tick runs, exactly as for the ArduPilot plant
(``sim.plants.firmware``): PX4's GCS MAVLink link (UDP 18570+i, read by a socket of ours) goes through ``link.radio``
to the ground stations, the scripted operator (``sim.px4.operator``, flying Offboard) and the timed events act, and
what the stations send goes through the radio to PX4 before the next physics step. Its data-link failsafe hears
exactly what the radio delivers.

Scenario time 0 is the moment PX4 is ready (``PX4Lockstep.boot``: a home, an EKF2 position, its version said).

PX4's simulated GPS stays on in the scenario's GPS-denied zones, for the ArduPilot plant's reason: the bridge gives
PX4 no wheel odometry, so without GPS EKF2 would have no position at all (and Offboard position control, Hold and
Return all need one), while the native vehicle dead-reckons there; switching it off would compare a blind autopilot
with a dead-reckoning one.

The record is the ArduPilot plant's: rows of (t, true x, true y, est x, est y, nav state, link delivery, rssi, speed
cmd, yaw rate cmd, armed, collisions so far), the times PX4 heard its station, the nav-state timeline; its figures,
summary and pictures are the firmware's (``sim.firmware.metrics``, ``sim.firmware.report``), read through the
attributes that say what the modes mean (``mode_names``, ``return_modes``, ``driving_mode``, ``home_modes``).
"""

from __future__ import annotations

import math
from pathlib import Path

from link.mission import Origin
from link.radio import subsystem_rng
from sim import registry
from sim.firmware.rangefinders import Rangefinders
from sim.plants.autopilot import AutopilotPlant
from sim.px4.lockstep import HOLD, NAV_STATES, OFFBOARD, RETURN, PX4Lockstep, nav_state_name
from sim.px4.operator import RETURN_MODES, PX4Operator
from sim.scenario import Scenario, Station

# PX4's data-link loss action per policy (Hold 1, Return 2) and its Offboard-loss action (the same Hold 5 or
# Return 3), from the registry
NAV_DLL_ACT = {p.name: p.nav_dll_act for p in registry.POLICIES if p.nav_dll_act is not None}
COM_OBL_RC_ACT = {p.name: p.com_obl_rc_act for p in registry.POLICIES if p.com_obl_rc_act is not None}
COM_OF_LOSS_T_MAX = 60.0  # s: the top of COM_OF_LOSS_T's range


def px4_params(policy: str, lnk_timeout: float, speed_limit: float) -> dict[str, float]:
    """What a PX4 run sets on top of the SITL defaults and airframe 1069, and why:
    - NAV_DLL_ACT per policy (1 Hold, 2 Return) and COM_DL_LOSS_T = the scenario's LNK_TIMEOUT, so PX4 reacts to the
      silence the native vehicle reacts to. It is a whole number of seconds in PX4: LNK_TIMEOUT rounded up, at least
      1 (PX4's documented range starts at 5 s, which ground stations enforce and PX4 itself does not).
    - The Offboard stream dies with the link too: the operator's setpoints ride the same radio as its heartbeat.
      PX4 then leaves Offboard after COM_OF_LOSS_T (default 1 s) for COM_OBL_RC_ACT (default Position mode, which
      without sticks falls through to its own fallbacks), long before COM_DL_LOSS_T: the baseline would measure the
      Offboard-loss fallback, not the data-link failsafe. So COM_OF_LOSS_T is its maximum, 60 s, later than any
      data-link loss of a scenario with LNK_TIMEOUT below about 55 s, and COM_OBL_RC_ACT is the policy's own
      action (5 Hold, 3 Return), so a stream lost for that long (or a LNK_TIMEOUT beyond it) still ends in the
      same behaviour. A patchy stream under a live link also never drops the rover out of Offboard then, as a
      heartbeat-only ArduPilot GUIDED target never does.
    - COM_FAIL_ACT_T 0: PX4 first holds COM_FAIL_ACT_T (5 s) before a failsafe action so that a pilot on the sticks
      can take over; nobody holds sticks here, and the native vehicle's return starts after LNK_TIMEOUT alone.
    - COM_DISARM_PRFLT -1: PX4 disarms a vehicle that does not "take off" within 10 s of arming; a rover standing
      at its start while the operator switches to Offboard has not failed a take-off.
    - RO_SPEED_LIM: PX4 rover's Offboard position target carries no speed (it drives at RO_SPEED_LIM, slowing to
      stop at the target), so the limit is the fastest speed the scenario's operator drives (its routes' speeds,
      at most the robot's own top speed); Return drives at it too."""
    if policy not in NAV_DLL_ACT:
        raise ValueError(f"policy {policy!r} is not one of {', '.join(NAV_DLL_ACT)}")
    if not (math.isfinite(lnk_timeout) and lnk_timeout > 0):
        raise ValueError(f"LNK_TIMEOUT must be a positive number of seconds, got {lnk_timeout!r}")
    if not (math.isfinite(speed_limit) and speed_limit > 0):
        raise ValueError(f"the speed limit must be a positive speed, got {speed_limit!r}")
    return {"NAV_DLL_ACT": NAV_DLL_ACT[policy], "COM_DL_LOSS_T": max(1, math.ceil(lnk_timeout - 1e-9)),
            "COM_OF_LOSS_T": COM_OF_LOSS_T_MAX, "COM_OBL_RC_ACT": COM_OBL_RC_ACT[policy], "COM_FAIL_ACT_T": 0,
            "COM_DISARM_PRFLT": -1, "RO_SPEED_LIM": round(speed_limit, 3)}


class PX4Plant(AutopilotPlant):
    """PX4 flying the scenario with its own data-link failsafe (see the module docstring). ``link`` is PX4 in
    lockstep with ``robot`` (``PX4Lockstep``: its process, its bridge, its ``tap``); ``rows`` its record per tick;
    ``heard`` the scenario times at which it received a frame from the operator's station."""

    kind = registry.PX4_PLANT.vehicles[0]
    policies: tuple[str, ...] = registry.PX4_PLANT.policies  # what this plant flies
    # what the modes mean, for the firmware's figures and pictures
    autopilot = "PX4"
    mode_names = NAV_STATES
    return_modes = RETURN_MODES
    rangefinders = False  # PX4's own failsafes use none (the companion's rover has them: sim.plants.px4_companion)
    driving_mode = OFFBOARD
    home_modes = (RETURN,)

    def __init__(self, scenario: Scenario, kind: str = kind, seed: int | None = None,
                 policy: str = registry.default_policy(kind), px4: Path | None = None, log_path: Path | None = None,
                 accept_timeout_s: float | None = None) -> None:
        """``px4``: the PX4 directory (``sim.px4.locate.find_px4``); ``accept_timeout_s``: its boot budget, the
        wall seconds it gets to connect to the simulator link."""
        self._set_scene(scenario, kind, seed, policy, px4, "PX4 directory")
        sc = scenario
        self.geo = Origin()  # the scenario frame's (0, 0) on the globe: the bridge's GPS origin
        speeds = [p[2] for p in (*sc.route, *sc.resume_route)]
        speed_limit = min(self.robot.max_speed, max(speeds, default=self.robot.max_speed))
        self.params = self._px4_params(policy, self.lnk_timeout, speed_limit)
        # the figures measure the reaction from the timeout PX4 was given (a whole number of seconds)
        self.lnk_timeout = float(self.params["COM_DL_LOSS_T"])
        options = {} if accept_timeout_s is None else {"accept_timeout_s": accept_timeout_s}
        if self.rangefinders:
            options["rangefinders"] = Rangefinders(self.world, subsystem_rng(self.seed, "rangefinders"))
        self.link = PX4Lockstep(self.world, self.robot, px4, self.params, self.geo, self.seed, log_path, **options)

    @staticmethod
    def _px4_params(policy: str, lnk_timeout: float, speed_limit: float) -> dict[str, float]:
        """PX4's parameters for ``policy`` (``px4_params``; the companion's plant sets its own)."""
        return px4_params(policy, lnk_timeout, speed_limit)

    # ----- the scenario around it ----------------------------------------------------------------------------
    def station(self, spec: Station, operator: bool) -> tuple[PX4Operator | None, None]:
        """The operator's station is the scripted operator itself; nobody runs the others."""
        if not operator:
            return None, None
        sc = self.scenario
        self.operator = PX4Operator(sc.route, sc.resume_route, self.geo, sc.attempts, sysid=spec.sysid,
                                    rejoin=sc.rejoin)
        return self.operator, None

    # ----- time ----------------------------------------------------------------------------------------------
    def _physics_time(self) -> float:
        return self.link.t_sim

    def _autopilot_estimate(self) -> tuple[float, float]:
        """EKF2's estimate, which the lockstep's tap reads in the true frame."""
        est = self.link.tap.estimate
        return est if est is not None else (math.nan, math.nan)

    def _mode_name(self, mode: int) -> str:
        return nav_state_name(mode)

    def started(self) -> str:
        """As every autopilot says it, and that PX4 arms only for a ground station it has heard."""
        return f"{super().started()}; it arms once it has heard a ground station"


__all__ = ["HOLD", "OFFBOARD", "RETURN", "PX4Plant", "px4_params"]
