"""Which autopilot the companion drives, and that autopilot's rules (docs/architecture.md §11, §11.2).

The driver learns which autopilot it drives from the first HEARTBEAT (``autopilot`` 3 ArduPilot, 12 PX4) and takes
that autopilot's rules object here: its mode numbers and how a mode is asked for, the streams it needs, the
parameters it reads and how they travel, how its estimator says a position is valid, and the steering that turns
the vehicle's speed and yaw rate into that autopilot's targets. Everything else in the driver is one code for both,
and asks the rules object rather than which autopilot it is (ArduPilot registers a backend once and never asks its
name again). PX4's numbers and encodings live in ``vehicle.companion.px4``.
"""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as apm

from vehicle.companion import px4
from vehicle.companion.targets import OffboardSteering, RoverSteering

# ArduPilot Rover's mode numbers (Rover/mode.h)
ROVER_MODES = {0: "MANUAL", 1: "ACRO", 3: "STEERING", 4: "HOLD", 5: "LOITER", 6: "FOLLOW", 7: "SIMPLE", 8: "DOCK",
               9: "CIRCLE", 10: "AUTO", 11: "RTL", 12: "SMART_RTL", 15: "GUIDED", 16: "INITIALISING"}
GUIDED, HOLD = 15, 4
ROVER_TYPES = (apm.MAV_TYPE_GROUND_ROVER, apm.MAV_TYPE_SURFACE_BOAT)  # the Rover firmware drives both

MODE_RETRY = 1.0  # s before a mode request not yet seen in the heartbeat is sent again
MODE_TRIES = 4  # ... and how often, before the return gives up on the autopilot
STREAMS = {  # message id -> interval (µs) the companion needs
    apm.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 100_000,
    apm.MAVLINK_MSG_ID_ATTITUDE: 100_000,
    apm.MAVLINK_MSG_ID_GPS_RAW_INT: 500_000,
    apm.MAVLINK_MSG_ID_EKF_STATUS_REPORT: 500_000,
    apm.MAVLINK_MSG_ID_DISTANCE_SENSOR: 100_000,  # every rangefinder and proximity sector (none: nothing sent)
}
GCS_SYSID_PARAMS = ("MAV_GCS_SYSID", "SYSID_MYGCS")  # ArduPilot 4.7+, and before


def rover_problem(m) -> str | None:
    """Why the autopilot whose HEARTBEAT is ``m`` cannot be driven by the companion, or None if it can."""
    if m.autopilot == apm.MAV_AUTOPILOT_PX4:
        return px4.rover_problem(m)
    if m.autopilot != apm.MAV_AUTOPILOT_ARDUPILOTMEGA:
        entry = apm.enums["MAV_AUTOPILOT"].get(m.autopilot)
        name = entry.name.removeprefix("MAV_AUTOPILOT_") if entry else str(m.autopilot)
        return f"the autopilot is {name}, not ArduPilot or PX4"
    if m.type not in ROVER_TYPES:
        entry = apm.enums["MAV_TYPE"].get(m.type)
        name = entry.name.removeprefix("MAV_TYPE_") if entry else str(m.type)
        return f"the autopilot is ArduPilot for a {name}, not ArduPilot Rover"
    return None


def is_autopilot_heartbeat(m) -> bool:
    """Whether ``m`` is an autopilot's HEARTBEAT (not a ground station's, a camera's or the companion's own)."""
    return m.get_type() == "HEARTBEAT" and m.autopilot != apm.MAV_AUTOPILOT_INVALID


def mode_name(mode: int | None) -> str:
    """An ArduPilot Rover mode by its name."""
    return "unknown" if mode is None else ROVER_MODES.get(mode, f"mode {mode}")


class ArduPilotRules:
    """How the companion drives ArduPilot Rover (``vehicle.companion.autopilot``): GUIDED, then velocity and
    turn-rate targets in the body frame, which the firmware executes for 3 s each; HOLD to stop; parameters cast to
    float."""

    name = "ArduPilot Rover"
    autopilot = apm.MAV_AUTOPILOT_ARDUPILOTMEGA
    drive, hold = GUIDED, HOLD
    lead: float | None = None  # targets only once in GUIDED: the firmware needs no stream before the switch
    mode_retry, mode_tries = MODE_RETRY, MODE_TRIES
    streams = STREAMS
    gcs_sysid_params = GCS_SYSID_PARAMS
    param_asks = GCS_SYSID_PARAMS  # read until one is known: the keepalive's system id
    estimate_reports = frozenset(("EKF_STATUS_REPORT",))  # whose flags say the estimate has a position
    stop_holds = False  # the dead-man's stop: a zero target, staying in GUIDED
    brakes = True  # a return released to HOLD brakes first with zero targets (HOLD alone coasts)
    steering = RoverSteering  # speeds governed, turns in place crept where the rover cannot pivot
    mode_name = staticmethod(mode_name)

    @staticmethod
    def set_mode(enc: apm.MAVLink, sysid: int, compid: int, mode: int):
        return enc.command_long_encode(sysid, compid, apm.MAV_CMD_DO_SET_MODE, 0,
                                       apm.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, mode, 0, 0, 0, 0, 0)

    @staticmethod
    def param_value(value: float, ptype: int) -> float:
        return float(value)

    @staticmethod
    def param_wire(value: float, ptype: int) -> float:
        return float(value)


class PX4Rules:
    """How the companion drives a PX4 rover (``vehicle.companion.px4``): a velocity stream from the moment a return
    holds the lease, Offboard asked for once it runs, Hold (AUTO_LOITER) to stop; parameters bytewise."""

    name = "PX4 rover"
    autopilot = apm.MAV_AUTOPILOT_PX4
    drive, hold = px4.OFFBOARD, px4.HOLD
    lead: float | None = px4.STREAM_LEAD
    mode_retry, mode_tries = px4.MODE_RETRY, px4.MODE_TRIES
    streams = px4.STREAMS
    gcs_sysid_params: tuple[str, ...] = ()  # PX4 counts any GCS-type HEARTBEAT: no system id to match
    param_asks = ("RO_YAW_P",)  # read until known: how its yaw loop answers a bearing (the steering's lead)
    estimate_reports = frozenset(("EKF_STATUS_REPORT", "ESTIMATOR_STATUS"))  # the same bits: 8 relative, 16 absolute
    stop_holds = True  # the dead-man's stop: Hold (a stream of stops would also keep a dead owner's Offboard alive)
    brakes = True  # a return released brakes with zero Offboard setpoints, then Hold, which stops shorter than Hold
    # at once. Measured beside PX4 (our plant): from 1 m/s, 0.340-0.345 m against Hold's 0.356-0.364 on the hard edge
    # (tests/test_companion_stop_lockstep.py, three runs each), 0.337-0.344 against 0.350-0.366 in the tunnel (four
    # runs each, two of 100 s), with one link loss in every run. (An earlier tree lost the link a second time in the
    # real-PX4 run of tests/test_px4_companion.py after the operator resumed, so Hold stayed for 2 cm; since the
    # operator drives home after a return (issue 41) no run lost it twice.)
    steering = OffboardSteering  # a speed and a bearing; a backward command an about-turn
    mode_name = staticmethod(px4.mode_name)
    set_mode = staticmethod(px4.set_mode)
    param_value = staticmethod(px4.param_value)
    param_wire = staticmethod(px4.param_wire)


Rules = type[ArduPilotRules] | type[PX4Rules]
RULES: dict[int, Rules] = {apm.MAV_AUTOPILOT_PX4: PX4Rules}


def rules_for(autopilot: int) -> Rules:
    """The rules for the autopilot a HEARTBEAT names (ArduPilot's for anything not PX4: ``rover_problem`` says
    whether it can be driven at all)."""
    return RULES.get(autopilot, ArduPilotRules)
