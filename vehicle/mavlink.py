"""The names this module had when it held the whole endpoint: it is now ``vehicle.endpoint`` (the composition) and
``vehicle.services`` (one module per MAVLink microservice). Kept so code written against it keeps working."""

from __future__ import annotations

from vehicle.endpoint import COMMANDS, HANDLED, Endpoint, vehicle_services
from vehicle.services.base import Counters, mav
from vehicle.services.signing import ACCESS, Access, access

__all__ = ["ACCESS", "COMMANDS", "HANDLED", "Access", "Counters", "Endpoint", "access", "mav", "vehicle_services"]
