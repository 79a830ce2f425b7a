"""The parameter protocol (docs/architecture.md §5): every parameter readable by anyone, writable by the owner, REAL32
on the wire.

PARAM_REQUEST_LIST and PARAM_REQUEST_READ are reads, answered to any station. PARAM_SET is a state change: from
anyone but the owner (while someone owns the vehicle) it is refused, and a value out of range is refused by the
parameter table; either way the station gets the parameter's PARAM_VALUE back unchanged (which is how a ground
station learns its write failed) and a STATUSTEXT saying why. An accepted value is saved to the .parm file, if the
vehicle has one, so the next boot starts with it.
"""

from __future__ import annotations

from pathlib import Path

from vehicle.params import SPECS, ParamError, save_parm
from vehicle.port import VehiclePort
from vehicle.services.base import Outbox, Service, Source, handles, mav


class ParamServer(Service):
    """The vehicle's parameter table over MAVLink; ``param_file`` (None: not saved) keeps accepted values."""

    def __init__(self, out: Outbox, vehicle: VehiclePort, param_file: Path | None = None) -> None:
        self.out = out
        self.vehicle = vehicle
        self.param_file = param_file

    def value(self, index: int) -> None:
        """PARAM_VALUE of the parameter at ``index`` of the table."""
        spec = SPECS[index]
        self.out.mav.param_value_send(spec.name.encode(), self.vehicle.params[spec.name], mav.MAV_PARAM_TYPE_REAL32,
                                      len(SPECS), index)

    @handles("PARAM_REQUEST_LIST")
    def _on_request_list(self, m, src: Source, t: float) -> None:
        for i in range(len(SPECS)):
            self.value(i)

    @handles("PARAM_REQUEST_READ")
    def _on_request_read(self, m, src: Source, t: float) -> None:
        if m.param_index >= 0:  # by index (an index past the table is not answered)
            if m.param_index < len(SPECS):
                self.value(m.param_index)
            return
        name = param_name(m.param_id)
        names = self.vehicle.params.names()
        if name in names:
            self.value(names.index(name))
        else:
            self.out.statustext(f"no parameter {name!r}", mav.MAV_SEVERITY_WARNING)

    @handles("PARAM_SET")
    def _on_set(self, m, src: Source, t: float) -> None:
        v = self.vehicle
        name = param_name(m.param_id)
        names = v.params.names()
        if name not in names:
            self.out.statustext(f"param set refused: no parameter {name!r}", mav.MAV_SEVERITY_WARNING)
            return
        if v.refuses(src.sysid):
            self.out.statustext(f"param set from {src.sysid} refused: GCS {v.status().book.owner} is in control",
                                mav.MAV_SEVERITY_WARNING)
        else:
            try:
                v.set_param(name, float(m.param_value))
                if self.param_file is not None:
                    save_parm(self.param_file, v.param_values())
            except ParamError as e:
                self.out.statustext(f"param set refused: {e}", mav.MAV_SEVERITY_WARNING)
            except OSError as e:  # in use until the next boot, which will not know it: say so
                self.out.statustext(f"param {name} set but not saved: {e.strerror or e}", mav.MAV_SEVERITY_ERROR)
        self.value(names.index(name))


def param_name(raw: bytes | str) -> str:
    """A param_id as text: up to its first NUL (16 characters, NUL-padded unless full)."""
    if isinstance(raw, bytes):
        raw = raw.decode("ascii", "replace")
    return raw.split("\x00", 1)[0]
