"""The ground side of the MAVLink mission protocol: upload, download and clear, one transfer at a time.

The station starts a transfer and hands this client the vehicle's MISSION_REQUEST(_INT), MISSION_COUNT,
MISSION_ITEM_INT and MISSION_ACK; a transfer that hears nothing for ``TRANSFER_TIMEOUT`` repeats its last step, and
gives up after ``TRANSFER_TRIES``. Like the station it has no clock and no socket: frames go out through the
station's encoder, time comes in as an argument.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from link.mission import Item, item_from_message

TRANSFER_TIMEOUT = 1.5  # s without an answer before the last step is repeated
TRANSFER_TRIES = 4


@dataclass
class Transfer:
    """A mission upload or download in progress."""

    kind: str  # "upload" | "download" | "clear"
    mission_type: int
    items: list[Item]
    count: int
    last_at: float
    tries: int = 1
    done: bool = False
    result: int | None = None
    expected: int = 0

    @property
    def ok(self) -> bool:
        return self.done and self.result == 0


class MissionClient:
    """One station's mission transfers to one vehicle (``target``/``target_comp``), encoded by ``mav``."""

    def __init__(self, mav, target: int, target_comp: int) -> None:
        self.mav, self.target, self.target_comp = mav, target, target_comp
        self.transfer: Transfer | None = None

    def upload(self, items: list[Item], mission_type: int, t: float) -> Transfer:
        items = [replace(it, seq=k, mission_type=mission_type) for k, it in enumerate(items)]
        self.transfer = Transfer("upload", mission_type, items, len(items), t)
        self.mav.mission_count_send(self.target, self.target_comp, len(items), mission_type)
        return self.transfer

    def download(self, mission_type: int, t: float) -> Transfer:
        self.transfer = Transfer("download", mission_type, [], -1, t)
        self.mav.mission_request_list_send(self.target, self.target_comp, mission_type)
        return self.transfer

    def clear(self, mission_type: int, t: float) -> Transfer:
        self.transfer = Transfer("clear", mission_type, [], 0, t)
        self.mav.mission_clear_all_send(self.target, self.target_comp, mission_type)
        return self.transfer

    def tick(self, t: float) -> None:
        """Repeat the last step of a transfer that heard nothing for ``TRANSFER_TIMEOUT``."""
        tr = self.transfer
        if tr is None or tr.done or t - tr.last_at < TRANSFER_TIMEOUT:
            return
        if tr.tries >= TRANSFER_TRIES:
            tr.done, tr.result = True, None
            return
        tr.tries += 1
        tr.last_at = t
        if tr.kind == "upload":
            self.mav.mission_count_send(self.target, self.target_comp, tr.count, tr.mission_type)
        elif tr.kind == "clear":
            self.mav.mission_clear_all_send(self.target, self.target_comp, tr.mission_type)
        elif tr.count < 0:
            self.mav.mission_request_list_send(self.target, self.target_comp, tr.mission_type)
        else:
            self.mav.mission_request_int_send(self.target, self.target_comp, len(tr.items), tr.mission_type)

    # ----- the vehicle's side of the protocol -------------------------------------------------------------------
    def on_mission_request_int(self, m, t: float) -> None:
        tr = self.transfer
        if tr is None or tr.kind != "upload" or tr.done or m.mission_type != tr.mission_type:
            return
        if not 0 <= m.seq < len(tr.items):
            return
        tr.last_at, tr.tries = t, 1
        it = tr.items[m.seq]
        self.mav.mission_item_int_send(self.target, self.target_comp, it.seq, it.frame, it.command, it.current,
                                       it.autocontinue, it.param1, it.param2, it.param3, it.param4, it.x, it.y,
                                       it.z, tr.mission_type)

    on_mission_request = on_mission_request_int

    def on_mission_ack(self, m, t: float) -> None:
        tr = self.transfer
        if tr is None or tr.done or m.mission_type != tr.mission_type or tr.kind == "download":
            return
        tr.done, tr.result = True, m.type

    def on_mission_count(self, m, t: float) -> None:
        tr = self.transfer
        if tr is None or tr.kind != "download" or tr.done or m.mission_type != tr.mission_type:
            return
        tr.count, tr.last_at, tr.tries = m.count, t, 1
        if m.count == 0:
            tr.done, tr.result = True, 0
            self.mav.mission_ack_send(self.target, self.target_comp, 0, tr.mission_type)
            return
        self.mav.mission_request_int_send(self.target, self.target_comp, 0, tr.mission_type)

    def on_mission_item_int(self, m, t: float) -> None:
        tr = self.transfer
        if tr is None or tr.kind != "download" or tr.done or m.seq != len(tr.items):
            return
        tr.items.append(item_from_message(m))
        tr.last_at, tr.tries = t, 1
        if len(tr.items) == tr.count:
            tr.done, tr.result = True, 0
            self.mav.mission_ack_send(self.target, self.target_comp, 0, tr.mission_type)
        else:
            self.mav.mission_request_int_send(self.target, self.target_comp, len(tr.items), tr.mission_type)
