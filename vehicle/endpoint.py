"""The vehicle's MAVLink endpoint (docs/architecture.md §4): bytes in, bytes out, as a composition of microservices.

``receive(data, t)`` parses frames with the generated ``returnlink`` dialect (``link.codec``), counts them, drops
what is addressed to another system or component, lets the signing gate judge the rest (docs/architecture.md §4.1),
tells the vehicle its owner was heard, and hands each message to the one service that declared it
(``vehicle.services``). ``tick(t)`` runs the services' time-driven work in order and returns every frame produced
since the last tick. It owns no clock and no socket: whatever loop drives the vehicle calls both.

Which services, the component id and the heartbeat's identity are parameters, so a companion computer
(docs/architecture.md §11) composes the same operator-control, lease, plan, parameter, signing and telemetry
services on component 191 (``vehicle.companion.app``), behind the router that decides what reaches it. A
composition may also pass ``forward``: it then receives what no service owns (a message type nobody declared, a
command nobody carries out, a frame addressed to another component) instead of its being dropped."""

from __future__ import annotations

from collections.abc import Callable, Hashable, Iterable
from pathlib import Path
from types import MethodType
from typing import Any, NamedTuple

from link.codec import read_datagram
from link.mission import Origin
from link.signing import Key, sim_stamp
from vehicle.keystore import KeyStore
from vehicle.port import VehiclePort
from vehicle.services.base import Counters, Outbox, Parts, Service, Source, mav, ticks
from vehicle.services.commands import CommandServer
from vehicle.services.mission import MissionService
from vehicle.services.mission_transfer import MissionServer
from vehicle.services.native import COMMANDS, HANDLED, vehicle_services
from vehicle.services.params import ParamServer
from vehicle.services.signing import Signing
from vehicle.services.telemetry import Telemetry

Forward = Callable[[Any, Source, float], None]  # (message, source, t): what no service of the composition owns


class Dispatch(NamedTuple):
    """How ``Endpoint.handle`` treats one message type, worked out once per type rather than per frame."""

    handler: Callable[[Any, Source, float], None] | None  # the owning service's handler; None: nobody's
    target_system: bool  # the message has a target_system field to check
    target_component: bool  # ... and a target_component field


# the target fields of every message of the dialect; anything else (UNKNOWN_n) has none
TARGETS = {cls.msgname: ("target_system" in cls.fieldnames, "target_component" in cls.fieldnames)
           for cls in mav.mavlink_map.values()}
NO_DISPATCH = Dispatch(None, False, False)
__all__ = ["COMMANDS", "HANDLED", "Endpoint", "Dispatch", "Forward", "Parts", "vehicle_services"]


class Endpoint:
    """MAVLink in, MAVLink out, for one vehicle core, seen through its port (``vehicle.port.VehiclePort``): one
    component, the services ``services(parts)`` builds."""

    def __init__(self, vehicle: VehiclePort, sysid: int = 1, compid: int = 1, origin: Origin | None = None,
                 boot_t: float = 0.0, param_file: Path | None = None, *, key: Key | None = None,
                 keystore: KeyStore | None = None, stamp: Callable[[float], int] = sim_stamp,
                 services: Callable[[Parts], Iterable[Service]] = vehicle_services, forward: Forward | None = None,
                 mav_type: int | None = None, autopilot: int = mav.MAV_AUTOPILOT_GENERIC) -> None:
        """``key`` (or ``keystore``, which also keeps the key and the signing timestamp on disk) turns signing on;
        ``stamp(t)`` is the signing clock in 10 µs units since 2015 (the wall clock on a real vehicle)."""
        self.vehicle = vehicle
        self.sysid, self.compid = sysid, compid
        self.out = Outbox(sysid, compid)
        self.mav = self.out.mav
        self.parser = _parser()
        self.counters = Counters()
        self.forward = forward
        self.sources: dict[int, Hashable] = {}  # sysid -> where its last trusted frame came from
        self._source: Hashable | None = None
        self.signed: set[int] = set()  # senders whose frames passed the signature check
        self.signing = Signing(self.out, vehicle, boot_t, stamp, key=key, keystore=keystore,
                               verdicts=self.counters.signing)
        composed = list(services(Parts(vehicle, self.out, self.counters, self.signing, sysid, compid,
                                       origin or Origin(), boot_t, param_file, mav_type, autopilot)))
        if self.signing not in composed:  # the gate's own service: key rotation and the timestamp file
            composed.append(self.signing)
        self.commands = CommandServer(self.out, self.counters, composed, unknown=forward)
        self.services: list[Service] = [self.commands, *composed]
        self.dispatch = _dispatch_table(self.services)
        self._ticks = [s.tick for s in self.services if ticks(s)]

    def service(self, cls: type) -> Any:
        """The composed service of class ``cls`` (None if the composition has none)."""
        return next((s for s in self.services if isinstance(s, cls)), None)

    # ----- input ---------------------------------------------------------------------------------------------
    def receive(self, data: bytes, t: float, source: Hashable | None = None) -> None:
        """Parse and handle whatever frames ``data`` holds; garbage is counted and dropped. ``source`` (a UDP
        address, opaque here) is remembered per sender, so the transport can keep the owner's (``pinned``)."""
        try:
            msgs = read_datagram(self.parser, data)
        except Exception:  # noqa: BLE001 - a hostile byte stream must never take the vehicle down
            self.counters.bad_frames += 1
            self.parser = _parser()
            return
        self._source = source
        try:
            for m in msgs:
                self.handle(m, t)
        finally:
            self._source = None  # frames handled later without a source are not attributed to this one

    def handle(self, m, t: float) -> None:
        """One message: counted, target-checked, signature-judged, then handed to the service that owns it.

        The type is asked once, the header read once, and the target fields and the handler come from a table per
        message type (``dispatch``) instead of attribute probes per frame: the teleop stream is 10 Hz per station."""
        kind = m.get_type()
        if kind == "BAD_DATA":
            self.counters.bad_frames += 1
            return
        header = m.get_header()
        sender = header.srcSystem
        if sender == self.sysid or sender == 0:
            return  # our own frames echoed back, or an anonymous sender
        self.counters.frames += 1
        how = self.dispatch.get(kind, NO_DISPATCH)
        ours = self._for_us(m, how)
        if not ours and self.forward is None:
            self.counters.wrong_target += 1
            return
        trusted = True
        if self.signing.key is not None:
            trusted = self.signing.check(m, sender, t)
            if trusted is None:
                return  # refused by the gate (counted and announced there)
        if trusted:  # an unsigned frame never counts as the owner heard: forged heartbeats keep nothing alive
            self.vehicle.heard(sender, t, header.seq)
            if self._source is not None:  # only a trusted frame may move a sender's address (at most 255 senders)
                self.sources[sender] = self._source
                if self.signing.key is not None:
                    self.signed.add(sender)
        handler = how.handler if ours else None
        if handler is None:
            handler = self.forward
            if handler is None:
                return
        try:
            handler(m, Source(sender, header.srcComponent, trusted), t)
        except (ValueError, TypeError, OverflowError, KeyError) as e:
            # a well-framed message with absurd content: refuse it, keep running, keep state
            self.counters.bad_frames += 1
            self.out.statustext(f"ignored {kind}: {e}", mav.MAV_SEVERITY_WARNING)
        except Exception as e:  # noqa: BLE001 - a fault in one handler must never take the vehicle down
            self.counters.handler_faults += 1
            self.out.statustext(f"fault handling {kind}: {type(e).__name__}: {e}", mav.MAV_SEVERITY_ERROR)

    def _for_us(self, m, how: Dispatch) -> bool:
        """The target-id rules: 0 is everyone; a message without target fields is for whoever hears it."""
        if how.target_system:
            ts = m.target_system
            if ts != 0 and ts != self.sysid:
                return False
        if how.target_component:
            tc = m.target_component
            return tc == 0 or tc == self.compid
        return True

    def pinned(self) -> list[Hashable]:
        """Addresses the transport must never drop from its peer table: the owner's and, with a key installed,
        every station signing with it (docs/architecture.md §3.9)."""
        keep = set(self.signed)  # with a key, every station that signs with it (it may become the owner)
        owner = self.vehicle.status().book.owner
        if owner is not None:
            keep.add(owner)
        return [self.sources[s] for s in keep if s in self.sources]

    # ----- output --------------------------------------------------------------------------------------------
    def replies(self) -> list[bytes]:
        """The frames produced since the last call or tick (answers to what was received), without running the
        tick: what a loop serving its link between ticks sends at once."""
        return self.out.take()

    def tick(self, t: float) -> list[bytes]:
        """Run every service's time-driven work and return every frame produced since the last tick."""
        for tick in self._ticks:
            tick(t)
        return self.out.take()

    def statustext(self, text: str, severity: int = mav.MAV_SEVERITY_INFO) -> None:
        self.out.statustext(text, severity)

    def close(self, t: float | None = None) -> None:
        """Shutdown: the last signing timestamp goes to disk."""
        self.signing.save_stamp(self.vehicle.status().t if t is None else t)

    # ----- what the composed services hold, under the names the simulator and the tests read -------------------
    @property
    def key(self) -> Key | None:
        return self.signing.key

    @property
    def telemetry(self) -> Telemetry | None:
        return self.service(Telemetry)

    @property
    def missions(self) -> MissionServer | None:
        """The mission transfer (stored lists, the upload in progress)."""
        service = self.service(MissionService)
        return None if service is None else service.transfer

    @property
    def param_file(self) -> Path | None:
        service = self.service(ParamServer)
        return None if service is None else service.param_file

    @param_file.setter
    def param_file(self, path: Path | None) -> None:
        self.service(ParamServer).param_file = path

    def custom_mode(self) -> int:
        return self.telemetry.custom_mode()

    def owner(self, kind: str) -> Service | None:
        """The service that handles messages of type ``kind`` here (None: nobody; they go to ``forward``)."""
        handler = self.dispatch.get(kind, NO_DISPATCH).handler
        return None if handler is None else handler.__self__


def _parser():
    parser = mav.MAVLink(None, 0, 0)
    parser.robust_parsing = True
    return parser


def _dispatch_table(services: list[Service]) -> dict[str, Dispatch]:
    """Every message type of the dialect with its target fields and the one service that declared it."""
    owners: dict[str, Callable] = {}
    for service in services:
        for kind, fn in type(service).MESSAGES.items():
            if kind in owners:
                raise ValueError(f"{kind} is declared by two services")
            owners[kind] = MethodType(fn, service)
    return {kind: Dispatch(owners.get(kind), ts, tc) for kind, (ts, tc) in TARGETS.items()}
