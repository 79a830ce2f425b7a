"""The simulator side of PX4's HIL messages, as pure functions (docs/architecture.md §10.1).

PX4's simulator_mavlink module takes the world from two messages: HIL_SENSOR every physics step (IMU, magnetometer,
barometer; its ``time_usec`` sets PX4's clock, which is what lockstep means) and HIL_GPS at 5-10 Hz; it answers
with HIL_ACTUATOR_CONTROLS, the outputs of its mixer (here airframe 1069: output 0 the right wheel, 1 the left,
each -1..1; zeros once disarmed, after which rover_differential publishes nothing and PX4 sends none). The rover
lives on flat ground in the scenario's frame: x north, y east (m from the GPS origin), yaw the heading (rad,
clockwise from north), so NED with z = 0; the body frame is FRD.

What PX4 checks, and so what must be right:
- the accelerometer measures specific force, so at rest it reads [0, 0, -g] in FRD (the ground holds the rover up);
  moving, the forward acceleration and the centripetal ``speed * yaw_rate`` to the side come on top;
- the magnetometer must agree with PX4's own world magnetic model at the GPS position, or EKF2 rejects the heading
  (its declination, inclination and strength checks); the field is the one at the origin (a few km of driving
  changes it by far less than those checks allow), rotated into the body by the heading;
- ``fields_updated`` says which fields are new: PX4 ignores the accelerometer, gyro, magnetometer or barometer
  of a message without its bits (its ``SensorSource`` masks);
- the GPS position is the scenario position projected around the origin the way PX4 projects it back into its
  local frame (azimuthal equidistant on a sphere of PX4's Earth radius, 6371 km), so PX4's local NED is the
  scenario frame; link.mission.Origin's conversion (6378.137 km) would put PX4's estimate 0.11 % off the truth,
  0.7 m after 600 m (measured);
- HIL_GPS's eph/epv are in cm and must be below EKF2's gates (EKF2_REQ_EPH 3 m, EKF2_REQ_EPV 5 m), with a 3D fix
  and enough satellites (EKF2_REQ_NSATS 6).

Magnetic field source: PX4's own tables (src/lib/world_magnetic_model/geo_magnetic_tables.hpp, WMM-2020 as of
2024.41, 10° grid), of which only the four grid points around the project's GPS origin are taken here as data, with
the tables' scale factors; between them the field is interpolated bilinearly, as PX4 does, so the bridge and EKF2
expect the same field. None of the project's dependencies computes the WMM (the small PyPI packages that do are old
models), and a full, newer model would match PX4's coarse table worse than PX4's own numbers do.

The IMU, magnetometer and barometer carry a little white noise (``SensorNoise``, drawn from the caller's seeded
generator): PX4's sensor voting marks a sensor whose every axis repeats the exact same value for about 100
samples as STALE and drops it ("MAG #0 failed: STALE!" on a rover driving straight with noise-free data:
measured), and a real sensor never does that. The GPS stays exact; its errors, biases and GPS-denied zones belong
to the plant on the simulator loop, which knows its scenario and its seeds.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mav

from link.mission import Origin

GRAVITY = 9.80665  # m/s^2, PX4's CONSTANTS_ONE_G
EARTH_RADIUS_M = 6371000.0  # PX4's CONSTANTS_RADIUS_OF_EARTH, the sphere of its map projection
SEA_LEVEL_HPA = 1013.25
SEA_LEVEL_K = 288.15
LAPSE_K_PER_M = 0.0065

# simulator_mavlink's SensorSource masks over HIL_SENSOR.fields_updated (SimulatorMavlink.hpp)
ACCEL = 0b111
GYRO = 0b111000
MAG = 0b111000000
BARO = 0b1101000000000  # abs_pressure, pressure_alt, temperature
DIFF_PRESS = 0b10000000000  # a rover has no airspeed sensor: never set
ALL_SENSORS = ACCEL | GYRO | MAG | BARO

GPS_PERIOD_US = 100_000  # HIL_GPS at 10 Hz: the top of PX4's 5-10 Hz and what its EKF2_GPS_DELAY is tuned for
GPS_EPH_CM = 50  # 0.5 m horizontal, 0.8 m vertical accuracy: a good fix, well inside EKF2's gates
GPS_EPV_CM = 80
GPS_SATELLITES = 12
FIX_3D = 3
COG_UNKNOWN = 65535  # HIL_GPS.cog when the course is not known (standing still)

# PX4's world magnetic model tables (geo_magnetic_tables.hpp in slgrobotics/PX4-Autopilot 33df162604: WMM-2020,
# date 2024.41257), the four grid points of the 10-degree cell around the project's GPS origin (link.mission.Origin,
# 47.397742 N 8.545594 E): {(lat, lon): value} in the tables' units, and the tables' scale factors.
WMM_CELL = (40.0, 0.0, 10.0)  # south-west corner (lat, lon) and size, degrees
WMM_DECLINATION = {(40, 0): 252, (40, 10): 629, (50, 0): 193, (50, 10): 719}
WMM_INCLINATION = {(40, 0): 20340, (40, 10): 20695, (50, 0): 24176, (50, 10): 24404}
WMM_INTENSITY = {(40, 0): 22117, (40, 10): 22515, (50, 0): 23819, (50, 10): 24073}
WMM_DECLINATION_DEG = 0.00545143529  # per table unit
WMM_INCLINATION_DEG = 0.00269892697
WMM_INTENSITY_NT = 2.04183477
NT_TO_GAUSS = 1e-5


@dataclass(frozen=True)
class RoverState:
    """The rover's truth at one instant, in the scenario frame (x north, y east from the GPS origin, yaw the
    heading): what the sensors are made from. ``speed`` and ``accel`` are along the body's forward axis."""

    x: float
    y: float
    yaw: float
    vn: float
    ve: float
    speed: float
    accel: float
    yaw_rate: float


@dataclass(frozen=True)
class SensorNoise:
    """Standard deviations of the white noise on each HIL_SENSOR axis: small against anything PX4 reacts to
    (a few cm of baro height, hundredths of a degree per second), large enough that no value repeats."""

    accel: float = 0.02  # m/s^2
    gyro: float = 0.002  # rad/s
    mag: float = 0.0005  # gauss (about 0.1 % of the field)
    baro: float = 0.005  # hPa (about 4 cm)


@dataclass(frozen=True)
class Wheels:
    """One HIL_ACTUATOR_CONTROLS as the rover sees it: each wheel's command -1..1 (forward positive), PX4's
    clock when it sent it, and whether it was armed (disarmed, PX4 sends zeros)."""

    left: float
    right: float
    time_usec: int
    armed: bool


def _bilinear(table: dict[tuple[int, int], int], lat: float, lon: float) -> float:
    lat0, lon0, size = WMM_CELL
    if not (lat0 <= lat <= lat0 + size and lon0 <= lon <= lon0 + size):
        raise ValueError(f"({lat:.4f}, {lon:.4f}) is outside the magnetic model cell taken from PX4's tables "
                         f"({lat0:g}..{lat0 + size:g} N, {lon0:g}..{lon0 + size:g} E): another GPS origin needs "
                         "its own four grid points")
    a, b = int(lat0), int(lon0)
    c, d = int(lat0 + size), int(lon0 + size)
    fy, fx = (lat - lat0) / size, (lon - lon0) / size
    south = table[(a, b)] + fx * (table[(a, d)] - table[(a, b)])
    north = table[(c, b)] + fx * (table[(c, d)] - table[(c, b)])
    return south + fy * (north - south)


def earth_field(lat: float, lon: float) -> tuple[float, float, float]:
    """The magnetic field (north, east, down) in gauss that PX4's world model expects at ``lat``/``lon``."""
    decl = math.radians(_bilinear(WMM_DECLINATION, lat, lon) * WMM_DECLINATION_DEG)
    incl = math.radians(_bilinear(WMM_INCLINATION, lat, lon) * WMM_INCLINATION_DEG)
    strength = _bilinear(WMM_INTENSITY, lat, lon) * WMM_INTENSITY_NT * NT_TO_GAUSS
    horizontal = strength * math.cos(incl)
    return horizontal * math.cos(decl), horizontal * math.sin(decl), strength * math.sin(incl)


def to_body(n: float, e: float, yaw: float) -> tuple[float, float]:
    """A horizontal NED vector in the body frame of a level vehicle with heading ``yaw`` (forward, right)."""
    c, s = math.cos(yaw), math.sin(yaw)
    return n * c + e * s, -n * s + e * c


def pressure_hpa(alt_m: float) -> float:
    """Absolute pressure of the standard atmosphere at ``alt_m`` above sea level (what PX4 turns back into a
    height with the same formula)."""
    return SEA_LEVEL_HPA * (1.0 - LAPSE_K_PER_M * alt_m / SEA_LEVEL_K) ** 5.25588


def temperature_c(alt_m: float) -> float:
    return SEA_LEVEL_K - LAPSE_K_PER_M * alt_m - 273.15


def hil_sensor(s: RoverState, time_usec: int, field_ned: tuple[float, float, float], alt_m: float,
               fields: int = ALL_SENSORS, noise: SensorNoise | None = None,
               normal: Callable[[], float] | None = None) -> mav.MAVLink_hil_sensor_message:
    """HIL_SENSOR for ``s`` at PX4 time ``time_usec``: specific force and rates in FRD (level ground: the side
    force is centripetal, z holds gravity), the field ``field_ned`` turned into the body, the barometer at
    ``alt_m``; with ``noise`` and ``normal`` (standard normal draws), each axis gets its noise added."""
    mx, my = to_body(field_ned[0], field_ned[1], s.yaw)
    ax, ay, az = s.accel, s.speed * s.yaw_rate, -GRAVITY
    gx, gy, gz = 0.0, 0.0, s.yaw_rate
    mz, p = field_ned[2], pressure_hpa(alt_m)
    if noise is not None and normal is not None:
        a, g, m = noise.accel, noise.gyro, noise.mag
        ax, ay, az = ax + a * normal(), ay + a * normal(), az + a * normal()
        gx, gy, gz = gx + g * normal(), gy + g * normal(), gz + g * normal()
        mx, my, mz = mx + m * normal(), my + m * normal(), mz + m * normal()
        p += noise.baro * normal()
    return mav.MAVLink_hil_sensor_message(time_usec, ax, ay, az, gx, gy, gz, mx, my, mz, p, 0.0, alt_m,
                                          temperature_c(alt_m), fields, 0)


def to_global(origin: Origin, x: float, y: float) -> tuple[float, float]:
    """(lat, lon) in degrees of the point ``x`` m north, ``y`` m east of ``origin``: the azimuthal equidistant
    projection about the origin on PX4's sphere, whose inverse PX4 applies to every GPS fix."""
    lat0, lon0 = math.radians(origin.lat), math.radians(origin.lon)
    xr, yr = x / EARTH_RADIUS_M, y / EARTH_RADIUS_M
    c = math.hypot(xr, yr)
    if c == 0.0:
        return origin.lat, origin.lon
    sin_c, cos_c = math.sin(c), math.cos(c)
    lat = math.asin(cos_c * math.sin(lat0) + xr * sin_c * math.cos(lat0) / c)
    lon = lon0 + math.atan2(yr * sin_c, c * math.cos(lat0) * cos_c - xr * math.sin(lat0) * sin_c)
    return math.degrees(lat), math.degrees(lon)


def to_local(origin: Origin, lat: float, lon: float) -> tuple[float, float]:
    """(x north, y east) in m of ``lat``/``lon`` around ``origin``: the inverse of ``to_global``."""
    lat0, lon0 = math.radians(origin.lat), math.radians(origin.lon)
    la, dlon = math.radians(lat), math.radians(lon) - lon0
    arg = math.sin(lat0) * math.sin(la) + math.cos(lat0) * math.cos(la) * math.cos(dlon)
    c = math.acos(max(-1.0, min(1.0, arg)))
    k = c / math.sin(c) if c > 0.0 else 1.0
    x = k * (math.cos(lat0) * math.sin(la) - math.sin(lat0) * math.cos(la) * math.cos(dlon)) * EARTH_RADIUS_M
    return x, k * math.cos(la) * math.sin(dlon) * EARTH_RADIUS_M


def hil_gps(s: RoverState, time_usec: int, origin: Origin) -> mav.MAVLink_hil_gps_message:
    """HIL_GPS for ``s``: the position around ``origin`` (flat ground at the origin's altitude), NED velocity,
    a 3D fix."""
    lat, lon = to_global(origin, s.x, s.y)
    ground = math.hypot(s.vn, s.ve)
    cog = COG_UNKNOWN if ground < 0.05 else round(math.degrees(math.atan2(s.ve, s.vn)) % 360.0 * 100) % 36000
    return mav.MAVLink_hil_gps_message(
        time_usec, FIX_3D, round(lat * 1e7), round(lon * 1e7), round(origin.alt * 1000), GPS_EPH_CM, GPS_EPV_CM,
        round(ground * 100), round(s.vn * 100), round(s.ve * 100), 0, cog, GPS_SATELLITES, 0, 0)


def gps_position(msg: mav.MAVLink_hil_gps_message, origin: Origin) -> tuple[float, float]:
    """The (x north, y east) a HIL_GPS says, around ``origin`` (the inverse of ``hil_gps``, to 1e-7 degrees)."""
    return to_local(origin, msg.lat / 1e7, msg.lon / 1e7)


class GpsClock:
    """When HIL_GPS is due: the first HIL_SENSOR, then every GPS_PERIOD_US of PX4 time."""

    def __init__(self, period_us: int = GPS_PERIOD_US) -> None:
        self.period_us = period_us
        self.next_us: int | None = None

    def due(self, time_usec: int) -> bool:
        if self.next_us is None or time_usec >= self.next_us:
            self.next_us = time_usec + self.period_us
            return True
        return False


def wheels(msg: mav.MAVLink_hil_actuator_controls_message) -> Wheels:
    """The wheel commands in one HIL_ACTUATOR_CONTROLS of airframe 1069 (output 0 right, 1 left), each clamped
    to -1..1 (a NaN, PX4's "disabled output", as 0)."""

    def unit(u: float) -> float:
        return 0.0 if u != u else -1.0 if u < -1.0 else 1.0 if u > 1.0 else float(u)

    armed = bool(msg.mode & mav.MAV_MODE_FLAG_SAFETY_ARMED)
    return Wheels(unit(msg.controls[1]), unit(msg.controls[0]), int(msg.time_usec), armed)


def rover_command(w: Wheels, track_m: float, max_wheel_speed: float) -> tuple[float, float]:
    """(forward speed m/s, yaw rate rad/s, FRD: positive turns right) of a differential rover whose wheels are
    ``track_m`` apart and reach ``max_wheel_speed`` at command 1: the mean of the wheel speeds, and their
    difference over the track (the left wheel faster turns right)."""
    left, right = w.left * max_wheel_speed, w.right * max_wheel_speed
    return (left + right) / 2.0, (left - right) / track_m
