"""The JSON SITL backend's packet contract, as pure functions and one small state machine (docs/architecture.md §10).

ArduPilot sends ``<HHI16H``: magic 18458, its frame rate, a frame counter and 16 PWM values in µs, once per
physics step it wants; the physics program answers each with ``"\\n" + json + "\\n"``. The firmware finds each
field by a plain string search, so a vector must follow its key directly (``"gyro":[...]``): the reply is written
with a fixed format string, which is also several times faster than ``json.dumps`` at 200 replies per second.

Lockstep, the physics owns time: each new frame is one physics step of 1/frame_rate s. A repeated frame counter
(the firmware resends when our answer was slow) gets the same answer and no step; a smaller one means the firmware
restarted. Anything else that arrives on the socket is malformed: counted and never answered.

PWM becomes the rover's (speed, yaw rate) command through the functions the firmware assigned its outputs
(SERVOn_FUNCTION, as the firmware reports them): skid steering (73 throttle left, 74 throttle right), which is
what the scenario's differential-drive rover is and what a firmware run configures, or ground steering (26) and
throttle (70), ArduPilot's own SITL car. Throttle ±100 % is the rover's ±max speed. Turning follows ArduPilot's
SITL rover model, whose tuning the firmware's controllers are used to: full differential turns at its skid turn
rate (140°/s); a steered car turns at speed over its radius (a 1.8 m turning circle at 35° wheel turn). The
scenario rover's own limits (top speed, turn rate, accelerations) still apply on top.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from enum import Enum

MAGIC = 18458
SERVO_PACKET = struct.Struct("<HHI16H")
PWM_MIN, PWM_MAX, PWM_TRIM = 1000.0, 2000.0, 1500.0
GRAVITY = 9.80665

# ArduPilot SRV_Channel functions this bridge understands
STEERING, THROTTLE, THROTTLE_LEFT, THROTTLE_RIGHT = 26, 70, 73, 74
DEFAULT_FUNCTIONS = {1: STEERING, 3: THROTTLE}  # SERVO1_FUNCTION, SERVO3_FUNCTION of ArduPilot's SITL rover
SKID_FUNCTIONS = {1: THROTTLE_LEFT, 3: THROTTLE_RIGHT}  # what a firmware run sets: the scenario rover is skid-steered

# the SITL rover's geometry (its turning circle at full lock, and that lock)
TURNING_CIRCLE_M = 1.8
MAX_WHEEL_TURN = math.radians(35.0)
SKID_TURN_RATE = math.radians(140.0)  # the SITL rover's turn rate at full differential


@dataclass(frozen=True)
class ServoFrame:
    frame_rate: int
    frame_count: int
    pwm: tuple[int, ...]


def parse_servo(data: bytes) -> ServoFrame | None:
    """The packet, or None when it is not a servo packet this bridge can use (size, magic, or a frame rate outside
    1..10000 Hz, which would make the physics step absurd)."""
    if len(data) != SERVO_PACKET.size:
        return None
    magic, rate, count, *pwm = SERVO_PACKET.unpack(data)
    if magic != MAGIC or not 1 <= rate <= 10000:
        return None
    return ServoFrame(rate, count, tuple(pwm))


class FrameVerdict(Enum):
    """What to do with one servo packet from the firmware."""

    STEP = "step"  # a new frame: step the physics once, answer with the new state
    REPEAT = "repeat"  # the same frame again: answer again, no step
    RESTART = "restart"  # the counter went back: the firmware restarted
    MALFORMED = "malformed"  # not a servo packet: no answer


class FrameRules:
    """What to do with each packet: the frame-counter rules above, and counts of each kind for the run's log."""

    def __init__(self) -> None:
        self.last: int | None = None
        self.counts = {v: 0 for v in FrameVerdict}

    def judge(self, frame: ServoFrame | None) -> FrameVerdict:
        if frame is None:
            v = FrameVerdict.MALFORMED
        elif self.last is None or frame.frame_count > self.last:
            v = FrameVerdict.STEP
        elif frame.frame_count == self.last:
            v = FrameVerdict.REPEAT
        else:
            v = FrameVerdict.RESTART
        if v is FrameVerdict.STEP or v is FrameVerdict.RESTART:
            self.last = frame.frame_count
        self.counts[v] += 1
        return v


def _unit(pwm: int) -> float:
    """A PWM value as -1..1 around trim; 0 (an output the firmware does not drive) is neutral."""
    if pwm <= 0:
        return 0.0
    u = (pwm - PWM_TRIM) / ((PWM_MAX - PWM_MIN) / 2)
    return -1.0 if u < -1.0 else 1.0 if u > 1.0 else u


class ServoMap:
    """PWM -> (forward speed m/s, yaw rate rad/s) for a rover whose top speed is ``max_speed``."""

    def __init__(self, max_speed: float, functions: dict[int, int] | None = None) -> None:
        self.max_speed = max_speed
        self.functions = dict(DEFAULT_FUNCTIONS if functions is None else functions)
        self._index = {f: ch - 1 for ch, f in self.functions.items()}
        self.skid = THROTTLE_LEFT in self._index and THROTTLE_RIGHT in self._index
        if not self.skid and not (STEERING in self._index and THROTTLE in self._index):
            raise ValueError(f"outputs {self.functions} drive neither steering+throttle (26, 70) nor skid "
                             "steering (73, 74)")

    def command(self, pwm: tuple[int, ...], speed_now: float) -> tuple[float, float]:
        ix = self._index
        if self.skid:
            left, right = _unit(pwm[ix[THROTTLE_LEFT]]), _unit(pwm[ix[THROTTLE_RIGHT]])
            # FRD: the left side faster than the right turns right (positive yaw rate)
            return (left + right) / 2 * self.max_speed, (left - right) / 2 * SKID_TURN_RATE
        throttle = _unit(pwm[ix[THROTTLE]])
        steer = _unit(pwm[ix[STEERING]])
        # a car turns at speed / radius; the radius at a given lock follows the SITL rover's geometry
        yaw_rate = 2.0 * speed_now * math.sin(steer * MAX_WHEEL_TURN) / (TURNING_CIRCLE_M * math.sin(MAX_WHEEL_TURN))
        return throttle * self.max_speed, yaw_rate


_REPLY = ('\n{{"timestamp":{:.6f},"imu":{{"gyro":[{:.6f},{:.6f},{:.6f}],"accel_body":[{:.6f},{:.6f},{:.6f}]}},'
          '"position":[{:.4f},{:.4f},{:.4f}],"velocity":[{:.4f},{:.4f},{:.4f}],"attitude":[{:.6f},{:.6f},{:.6f}]}}\n')


# the same with the six rangefinders' distances (m), which the backend reads as "rng_1" ... "rng_6"
_REPLY_RNG = _REPLY[:-3] + ''.join(f',"rng_{n}":{{:.3f}}' for n in range(1, 7)) + '}}\n'


def state_reply(t: float, x: float, y: float, yaw: float, vx: float, vy: float, speed: float, accel: float,
                yaw_rate: float, ranges: tuple[float, ...] | None = None) -> bytes:
    """The JSON answer for a ground vehicle on flat ground: position and velocity NED (x north, y east), attitude
    [roll, pitch, yaw], gyro in body FRD, and specific force in body FRD — forward acceleration, the centripetal
    ``speed * yaw_rate`` to the side, and -g on z (the ground holds it up). ``ranges``: the six rangefinders'
    distances (``sim.firmware.rangefinders``), or None for a rover without them (no ``rng_N`` keys)."""
    if ranges is None:
        return _REPLY.format(t, 0.0, 0.0, yaw_rate, accel, speed * yaw_rate, -GRAVITY, x, y, 0.0, vx, vy, 0.0,
                             0.0, 0.0, yaw).encode()
    return _REPLY_RNG.format(t, 0.0, 0.0, yaw_rate, accel, speed * yaw_rate, -GRAVITY, x, y, 0.0, vx, vy, 0.0,
                             0.0, 0.0, yaw, *ranges).encode()
