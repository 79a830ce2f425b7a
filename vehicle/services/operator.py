"""Operator control and leases on the wire (docs/architecture.md §3, §4): who holds the vehicle, and every lease
transition told.

REQUEST_OPERATOR_CONTROL takes or gives up the root lease (the upstream GCS operator-control microservice),
LEASE_CLAIM and LEASE_EXPIRE move along the execution-lease sequence; the lease book decides, this service only
translates. Each tick it announces what the vehicle's lease transitions produced: a LEASE_EVENT per transition
and a STATUSTEXT per notice. A companion computer serves the same on its own component.
"""

from __future__ import annotations

from vehicle.port import VehiclePort
from vehicle.services.base import Outbox, Reply, Service, Source, boot_ms, command, mav, whole, wire_index
from vehicle.services.commands import answer

MAX_EPOCH = 65535  # LEASE_CLAIM / LEASE_EXPIRE param1 (an epoch is 16 bits on the wire)
MAX_INDEX = 65534  # an execution lease's index (65535 is NO_INDEX)
CLAIM_CURRENT = -1  # LEASE_CLAIM param2: the current operator lease, not yet claimed


class OperatorControl(Service):
    """The root lease and the execution leases as commands, and their transitions as announcements."""

    def __init__(self, out: Outbox, vehicle: VehiclePort, boot_t: float = 0.0) -> None:
        self.out = out
        self.vehicle = vehicle
        self.boot_t = boot_t

    @command(mav.MAV_CMD_REQUEST_OPERATOR_CONTROL)
    def _request_control(self, p: tuple, src: Source, t: float) -> Reply:
        """p1 1 request / 0 release, p2 allow takeover, p4 the requester (only itself); ACK param2 = the epoch."""
        sender = src.sysid
        requester = int(p[3]) or sender
        if requester != sender:
            self.out.statustext("operator control: a station can only request control for itself",
                                mav.MAV_SEVERITY_WARNING)
            return mav.MAV_RESULT_DENIED, 0
        v = self.vehicle
        request = p[0] >= 0.5
        chk = v.operator_control(sender, src.compid, t, request, allow_takeover=p[1] >= 0.5)
        if not request:
            return answer(self.out, chk, "release", sender)
        if chk.executes:  # (the lease granted is the new epoch's current one)
            return mav.MAV_RESULT_ACCEPTED, chk.lease.epoch if chk.lease is not None else 0
        return answer(self.out, chk, "control request", sender)

    @command(mav.MAV_CMD_LEASE_CLAIM)
    def _claim(self, p: tuple, src: Source, t: float) -> Reply:
        """p1 epoch, p2 index (-1: the current operator lease); ACK param2 = the index claimed."""
        epoch, index = whole(p[0]), whole(p[1])
        if epoch is None or index is None or not 0 <= epoch <= MAX_EPOCH or not CLAIM_CURRENT <= index <= MAX_INDEX:
            self.out.statustext("lease claim: epoch or index out of range", mav.MAV_SEVERITY_WARNING)
            return mav.MAV_RESULT_DENIED, 0
        chk = self.vehicle.claim(src.sysid, epoch, index, t)
        if chk.executes and chk.lease is not None:
            return mav.MAV_RESULT_ACCEPTED, chk.lease.index
        return answer(self.out, chk, "lease claim", src.sysid)

    @command(mav.MAV_CMD_LEASE_EXPIRE)
    def _expire(self, p: tuple, src: Source, t: float) -> Reply:
        """p1 epoch, p2 index (must be current): the explicit expiration trigger."""
        epoch, index = whole(p[0]), whole(p[1])
        if epoch is None or index is None or not 0 <= epoch <= MAX_EPOCH or not 0 <= index <= MAX_INDEX:
            self.out.statustext("lease expire: epoch or index out of range", mav.MAV_SEVERITY_WARNING)
            return mav.MAV_RESULT_DENIED, 0
        return answer(self.out, self.vehicle.expire(src.sysid, epoch, index, t), "lease expire", src.sysid)

    def tick(self, t: float) -> None:
        """LEASE_EVENT for every transition since the last tick, then a STATUSTEXT for every notice: drained from
        the vehicle's queue, which only it fills."""
        events, notices = self.vehicle.drain()
        for ev in events:
            self.out.mav.lease_event_send(boot_ms(ev.t, self.boot_t), ev.epoch, wire_index(ev.expired),
                                          wire_index(ev.current), int(ev.reason), int(ev.holder))
        for text in notices:
            self.out.statustext(text, mav.MAV_SEVERITY_NOTICE)
