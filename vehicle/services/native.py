"""The native vehicle's composition: which microservices it serves and how they are wired to each other.

``vehicle_services`` is the factory ``vehicle.endpoint.Endpoint`` calls by default; a companion computer passes
its own (the same classes, fewer of them, another identity). ``VEHICLE_SERVICES``, ``COMMANDS`` and ``HANDLED``
say what the native vehicle answers, for tools and tests that enumerate it without building a vehicle.
"""

from __future__ import annotations

from collections.abc import Mapping

from link.linkmap_format import FILE_NAME, encode
from vehicle.port import Snapshot
from vehicle.services.actions import VehicleActions
from vehicle.services.base import Parts, Service, mav
from vehicle.services.commands import CommandServer
from vehicle.services.ftp import Files, FtpServer
from vehicle.services.mission import MissionService
from vehicle.services.operator import OperatorControl
from vehicle.services.params import ParamServer
from vehicle.services.signing import Signing
from vehicle.services.telemetry import DEFAULT_RATES, Telemetry
from vehicle.services.teleop import Teleop


def vehicle_services(p: Parts, *, rates: Mapping[int, float] = DEFAULT_RATES, drives: bool = True) -> list[Service]:
    """The native vehicle's microservices, in the order their ticks run: lease announcements, plan progress and
    upload time-outs, the signing clock, then telemetry (which reports what the others changed).

    A companion computer composes the same list with the streams it owns (``rates``) and without the teleop
    service (``drives`` False): its robot is the autopilot, which the operator's setpoints reach directly."""
    missions: MissionService  # (telemetry's MISSION_CURRENT counts the stored plan's items)
    telemetry = Telemetry(p.out, p.vehicle, p.origin, p.boot_t, lambda: (p.counters.frames, p.counters.bad_frames),
                          lambda: len(missions.transfer.lists[mav.MAV_MISSION_TYPE_MISSION]),
                          mav_type=p.mav_type, autopilot=p.autopilot, rates=rates)
    missions = MissionService(p.out, p.vehicle, p.origin, telemetry.emit)
    teleop = [Teleop(p.out, p.vehicle, p.counters, p.sysid)] if drives else []
    return [OperatorControl(p.out, p.vehicle, p.boot_t), missions, p.signing, telemetry,
            ParamServer(p.out, p.vehicle, p.param_file), *teleop, VehicleActions(p.out, p.vehicle),
            FtpServer(p.out, vehicle_files(p.vehicle))]


def vehicle_files(vehicle: Snapshot) -> Files:
    """What a vehicle offers as files over MAVLink FTP: its link map (docs/architecture.md §6), made when a station
    opens it."""
    return {FILE_NAME: lambda: encode(vehicle.linkmap_cells())}


# the service classes of the native composition, with the command server every composition has
VEHICLE_SERVICES: tuple[type[Service], ...] = (CommandServer, OperatorControl, MissionService, Signing, Telemetry,
                                               ParamServer, Teleop, VehicleActions, FtpServer)
COMMANDS = {cid: fn for cls in VEHICLE_SERVICES for cid, fn in cls.COMMANDS.items()}  # MAV_CMD id -> handler
HANDLED = frozenset(kind for cls in VEHICLE_SERVICES for kind in cls.MESSAGES)  # message types the vehicle answers
