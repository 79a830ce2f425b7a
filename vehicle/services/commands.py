"""The command microservice (docs/architecture.md §3.9, §4): COMMAND_LONG and COMMAND_INT in, exactly one COMMAND_ACK
out.

The services of a component declare the commands they carry out (``@command(mav.MAV_CMD_...)``); this one owns
only what every command shares: the table from command id to handler, the parameter check of
``link.command_params`` (a bad parameter is refused by name, never half-executed), the retry window (a retry or a
late copy of any command of the last RETRY_WINDOW seconds gets the first answer again and is never executed
twice), and the guarantee of one answer, also when a handler raises. ``answer`` turns a lease verdict into the
MAV_RESULT every lease-checked command answers with, in one table.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from types import MethodType
from typing import Any

from link.command_params import check_command, command_name, command_values
from vehicle.lease import Check, RejectReason, Verdict
from vehicle.retries import RetryWindow, command_key
from vehicle.services.base import Counters, Outbox, Reply, Service, Source, handles, mav

RETRY_WINDOW = 3.0  # s: an identical command from the same sender within this is a retry or a late copy

REJECT_RESULT = {
    RejectReason.NOT_IN_CONTROL: mav.MAV_RESULT_NOT_IN_CONTROL,
    RejectReason.WRONG_EPOCH: mav.MAV_RESULT_DENIED,
    RejectReason.EXPIRED: mav.MAV_RESULT_DENIED,
    RejectReason.INVALID: mav.MAV_RESULT_DENIED,
}

Unknown = Callable[[Any, Source, float], None]  # (message, source, t): a command no service of ours carries out


def answer(out: Outbox, chk: Check, what: str, sender: int) -> Reply:
    """The reply to a command the lease rules judged: executed, queued behind the current lease, or refused (with
    a STATUSTEXT saying why)."""
    if chk.verdict is Verdict.EXECUTE:
        return mav.MAV_RESULT_ACCEPTED, 0
    if chk.verdict is Verdict.QUEUE:
        return mav.MAV_RESULT_IN_PROGRESS, 0
    out.statustext(f"{what} from {sender} refused: {chk.detail or chk.reason.name}", mav.MAV_SEVERITY_WARNING)
    return REJECT_RESULT.get(chk.reason, mav.MAV_RESULT_DENIED), 0


class CommandServer(Service):
    """Receives the commands of a component and dispatches them to the services that declared them.

    ``unknown``, when given, receives a command no service declares instead of the UNSUPPORTED answer (a
    companion computer passes it on to its autopilot, which answers it)."""

    def __init__(self, out: Outbox, counters: Counters, services: Iterable[Service], unknown: Unknown | None = None,
                 window: float = RETRY_WINDOW) -> None:
        self.out = out
        self.counters = counters
        self.unknown = unknown
        self.answered = RetryWindow(window)
        self.table: dict[int, Callable[[tuple, Source, float], Reply]] = {}
        for service in services:
            for cid, fn in type(service).COMMANDS.items():
                if cid in self.table:
                    raise ValueError(f"{command_name(cid)} is declared by two services")
                self.table[cid] = MethodType(fn, service)

    @handles("COMMAND_LONG")
    def _on_long(self, m, src: Source, t: float) -> None:
        self.run(m.command, (m.param1, m.param2, m.param3, m.param4, m.param5, m.param6, m.param7), src, t, m)

    @handles("COMMAND_INT")
    def _on_int(self, m, src: Source, t: float) -> None:
        self.run(m.command, (m.param1, m.param2, m.param3, m.param4, float(m.x), float(m.y), m.z), src, t, m)

    def run(self, command: int, p: tuple, src: Source, t: float, m: Any = None) -> None:
        """Answer one command message (its id and seven parameters) exactly once."""
        handler = self.table.get(command)
        if handler is None and self.unknown is not None:
            self.unknown(m, src, t)
            return
        key = command_key(src.sysid, src.compid, command, p)
        prev = self.answered.seen(key, t)
        if prev is not None:
            self.counters.command_retries += 1
            self._ack(command, prev.result, prev.param2, src)
            return
        self.counters.commands += 1
        bad_param = check_command(command, p) if handler is not None else None
        if handler is None:
            self.counters.unsupported += 1
            result, param2 = mav.MAV_RESULT_UNSUPPORTED, 0
        elif bad_param is not None:  # out of range, NaN or infinite where it matters: never half-executed
            self.out.statustext(f"refused: {bad_param}", mav.MAV_SEVERITY_WARNING)
            result, param2 = mav.MAV_RESULT_DENIED, 0
        else:
            try:
                result, param2 = handler(command_values(command, p), src, t)
            except (ValueError, OverflowError) as e:  # NaN or infinity where a number is needed
                self.out.statustext(f"{command_name(command)} refused: {e}", mav.MAV_SEVERITY_WARNING)
                result, param2 = mav.MAV_RESULT_DENIED, 0
            except Exception as e:  # noqa: BLE001 - answered FAILED, counted, and the vehicle keeps running
                self.counters.handler_faults += 1
                self.out.statustext(f"fault in {command_name(command)}: {type(e).__name__}: {e}",
                                    mav.MAV_SEVERITY_ERROR)
                result, param2 = mav.MAV_RESULT_FAILED, 0
        self.answered.remember(key, result, param2, t)
        self._ack(command, result, param2, src)

    def _ack(self, command: int, result: int, param2: int, src: Source) -> None:
        self.out.mav.command_ack_send(command, result, 0, int(param2), src.sysid, src.compid)
