"""The router's verdict on a ground frame meant for the autopilot, completed by the vehicle's port where the native
endpoint would ask its own core: a plain client admitted to the root (LEASE_AUTOGRANT), a teleop-like frame judged
under the owner's lease (``take_manual``), a refusal counted (docs/architecture.md §3.4, §11).

``vehicle.companion.router`` decides from the lease book alone and stays pure; this is the one place its ADMIT and
TAKE answers become calls on the port, so the companion's frame handling only forwards or refuses.
"""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as apm

from vehicle.companion import router
from vehicle.companion.router import Action, Authority, Decision
from vehicle.port import VehiclePort

STARTING = Decision(Action.REFUSE, apm.MAV_RESULT_TEMPORARILY_REJECTED,
                    "the companion is starting (waiting for the autopilot's position estimate)")


def decide(v: VehiclePort | None, access: Authority, sender: int, scomp: int, t: float, *, trusted: bool,
           keyed: bool, autopilot_down: str | None = None) -> Decision:
    """Whether the frame of ``sender`` (component ``scomp``) needing ``access`` may reach the autopilot at ``t``:
    anyone may read; nothing else passes before the vehicle ``v`` runs or while the autopilot is down
    (``autopilot_down``: why, e.g. "the autopilot is not answering"); otherwise the router's decision over the
    lease book, with the port asked to admit or to take the teleop lease as the router says."""
    if access is Authority.READ:
        return router.FORWARD
    if v is None:
        return STARTING
    if autopilot_down is not None:
        return Decision(Action.REFUSE, apm.MAV_RESULT_TEMPORARILY_REJECTED, autopilot_down)
    d = router.decide(access, sender, scomp, v.status().book, t, trusted=trusted, keyed=keyed)
    if d.kind is Action.ADMIT:
        v.admit(sender, scomp, t)
        d = router.decide(access, sender, scomp, v.status().book, t, trusted=trusted, keyed=keyed)
        if d.kind is Action.ADMIT:  # (cannot happen: the grant was just decided possible)
            d = Decision(Action.REFUSE, apm.MAV_RESULT_DENIED, "not granted")
    if d.kind is Action.TAKE:
        chk = v.take_manual(sender, scomp, t)
        if chk.executes:
            return router.FORWARD
        reason = chk.reason or router.RejectReason.INVALID
        return Decision(Action.REFUSE, router.REJECT_RESULT[reason],
                        f"{chk.detail or reason.value}; {router.lease_text(v.status().book)}")
    if d.kind is Action.REFUSE:
        v.refused()  # (take_manual counts its own refusals)
    return d
