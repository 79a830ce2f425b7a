"""The firmware plant: the real ArduPilot Rover firmware in a scenario's world, flying its own failsafes, for
``sim.runner.Run`` (``returnlink sim run SCENARIO --vehicle ardurover``).

The scenario's pymunk rover (walls stay collisions) is driven by the firmware's servo outputs through the JSON
bridge, lockstep (``sim.firmware.lockstep``): the firmware asks for a physics step per frame (200 Hz), the physics
steps and answers, so simulated time is the physics' own and the run goes as fast as both processes allow. Every
20 ms of it (the native tick) the loop's tick runs: the firmware's MAVLink traffic (its SERIAL0, sent to a UDP
socket of ours) goes through ``link.radio`` to the ground stations, the scripted operator and the scenario's timed
events act, and what the stations send goes through the radio to the firmware, before its next frame. Its GCS
failsafe hears exactly what the radio delivers. The same seed gives the same radio fates, sensors-free physics and
operator as the native rover flying the scenario, so the firmware's failsafes are compared in the same world.

Scenario time 0 is the moment the firmware is ready (``Lockstep.boot``: home, EKF on GPS, pre-arm checks passed).

The firmware's own simulated GPS stays on in the scenario's GPS-denied zones: ArduPilot's SITL rover gets no wheel
odometry from this bridge, so without GPS its EKF would have no position source at all, while the native vehicle
dead-reckons on odometry there. Switching it off would compare a blind firmware with a dead-reckoning vehicle,
measuring the sensor suite rather than the link-loss behaviour this comparison is for.

Only the operator's station runs software (``sim.firmware.operator.FirmwareOperator``, a person flying the firmware
in GUIDED); the others are antennas the radio carries to and nobody listens at. The firmware has no leases: its
record is its own rows (mode, arming, collisions) and the times it heard its station, and its figures are read
from its mode timeline (``sim.firmware.metrics``).
"""

from __future__ import annotations

import math
from pathlib import Path

from link.radio import subsystem_rng
from sim import registry
from sim.firmware import rangefinders
from sim.firmware.lockstep import MODE_NAMES, SKID_PARAMS, SPEEDUP, Lockstep
from sim.firmware.operator import RETURN_MODES, FirmwareOperator
from sim.firmware.rangefinders import Rangefinders
from sim.plants.autopilot import AutopilotPlant
from sim.scenario import Scenario, Station
from vehicle.companion.setup import NEEDS

# per policy, from the registry; the companion's is the backstop: Hold once a dead companion's keepalive stops
# (docs/architecture.md §11); the applet's too: Hold once its return has not found the link by FS_GCS_TIMEOUT, or
# it died (sim.plants.applet)
FS_ACTION: dict[str, int] = {p.name: p.fs_action for p in registry.POLICIES if p.fs_action is not None}


def firmware_params(policy: str, lnk_timeout: float, max_speed: float,
                    max_accel: float | None = None) -> dict[str, float]:
    """What a firmware run sets on top of ArduPilot's own SITL rover defaults, and why:
    - the policy's failsafe: FS_GCS_ENABLE 1, FS_ACTION per policy, FS_GCS_TIMEOUT = the scenario's LNK_TIMEOUT
      (at least 2 s, the firmware's range), so it reacts to the same silence the native vehicle does;
    - FS_THR_ENABLE 0: nobody holds an RC transmitter here, and its radio failsafe would fire at once;
    - CRUISE_SPEED/CRUISE_THROTTLE matching the bridge's throttle scale (full throttle = the rover's top speed), so
      the speed controller's feed-forward is right from the start;
    - ATC_ACCEL_MAX = the rover's own acceleration limit (``max_accel``), as ArduPilot's tuning guide asks of an
      owner: left at its 1 m/s^2 default, the firmware took 1.0 s to reach 1 m/s where the rover itself (and the
      native vehicle on it) takes 0.7 s, which every firmware policy's return paid (measured: tunnel, seed 1);
    - WP_RADIUS 1 m: a GUIDED position target counts as reached where the scripted operator moves on;
    - skid steering (SERVO1_FUNCTION 73, SERVO3_FUNCTION 74): the scenario's rover is a differential drive that
      turns on the spot, as the native vehicle's is, so only the autopilot differs between the two (as a car, the
      firmware had to drive forward to turn round and wedged itself in the 3.6 m culvert);
    - for the companion, the rover's six rangefinders (``sim.firmware.rangefinders``: RNGFNDn_TYPE 100, the
      SITL's, with their orientations and limits), which the firmware reports as DISTANCE_SENSOR and the companion
      keeps its return off (docs/architecture.md §11.4).
    For the companion the GCS failsafe is its backstop, not the link-loss policy: its keepalive is what the firmware
    hears, so FS_GCS_TIMEOUT is what ``returnlink companion --check`` asks for (2..5 s), and every other parameter
    on that list is set to the value ``--configure`` would set (``vehicle.companion.setup.NEEDS``), so the run
    starts from a firmware the companion's own check passes."""
    params = {"FS_GCS_ENABLE": 1, "FS_ACTION": FS_ACTION[policy], "FS_GCS_TIMEOUT": max(2.0, lnk_timeout),
              "FS_THR_ENABLE": 0, "CRUISE_SPEED": round(max_speed / 2, 3), "CRUISE_THROTTLE": 50, "WP_RADIUS": 1.0,
              **SKID_PARAMS}
    if max_accel is not None:
        params["ATC_ACCEL_MAX"] = round(max_accel, 3)
    if registry.BY_POLICY[policy].beside:
        params |= rangefinders.params()
        for need in NEEDS:
            value = params.get(need.name, 0.0)  # ArduPilot's default of the others is 0
            params[need.name] = value if need.ok(value) else need.fix(value)
    return params


class FirmwarePlant(AutopilotPlant):
    """The firmware flying the scenario with its own failsafes (see the module docstring). ``link`` is the
    firmware in lockstep with ``robot`` (``Lockstep``: its process, its bridge, its ``tap``); ``rows`` its record
    per tick: (t, true x, true y, est x, est y, mode, link delivery, rssi, speed cmd, yaw rate cmd, armed,
    collisions so far); ``heard`` the scenario times at which it received a frame from the operator's station."""

    kind = registry.FIRMWARE_PLANT.vehicles[0]
    policies: tuple[str, ...] = registry.FIRMWARE_PLANT.policies  # what this plant flies
    rangefinders = False  # the firmware's own failsafes use none (the companion's rover has them: issue 41)
    autopilot = "ArduPilot"
    # what the modes mean, for the figures and pictures
    mode_names = MODE_NAMES
    return_modes = RETURN_MODES

    def __init__(self, scenario: Scenario, kind: str = kind, seed: int | None = None,
                 policy: str = registry.default_policy(kind), firmware: Path | None = None,
                 log_path: Path | None = None, speedup: float = SPEEDUP) -> None:
        """``speedup``: the firmware's own pace; lockstep runs leave the pace to the bridge (``SPEEDUP``), a
        server in real time asks for 1."""
        self._set_scene(scenario, kind, seed, policy, firmware, "firmware binary")
        # the companion's rover carries rangefinders, which it hears through the firmware (issue 41); the
        # firmware's own failsafes use none, and their runs stay as they were measured
        rangefinders = (Rangefinders(self.world, subsystem_rng(self.seed, "rangefinders"))
                        if self.rangefinders else None)
        self.link = Lockstep(self.world, self.robot, firmware,
                             firmware_params(policy, self.lnk_timeout, self.robot.max_speed,
                                             self.robot.max_accel), speedup, log_path, rangefinders=rangefinders)

    def _make_operator(self, sc: Scenario) -> FirmwareOperator:
        """The scripted operator: a person flying the firmware in GUIDED from the scenario's station."""
        return FirmwareOperator(sc.route, sc.resume_route, self.origin, sc.attempts,
                                sysid=sc.station(sc.operator_station).sysid, rejoin=sc.rejoin)

    # ----- the scenario around it ----------------------------------------------------------------------------
    def station(self, spec: Station, operator: bool) -> tuple[FirmwareOperator | None, None]:
        """The operator's station is the scripted operator itself (its own MAVLink, deciding as it sends); nobody
        runs the others."""
        if not operator:
            return None, None
        self.operator = self._make_operator(self.scenario)
        return self.operator, None

    # ----- time ----------------------------------------------------------------------------------------------
    def _physics_time(self) -> float:
        return self.link.t_fw

    def _connected(self) -> bool:
        return self.link.fw_addr is not None

    def _autopilot_estimate(self) -> tuple[float, float]:
        """The firmware's EKF estimate in its local frame (its origin the start), moved into the true frame."""
        est = self.link.tap.estimate
        return (self.origin[0] + est[0], self.origin[1] + est[1]) if est is not None else (math.nan, math.nan)

    def _mode_name(self, mode: int) -> str:
        return MODE_NAMES.get(mode, str(mode))
