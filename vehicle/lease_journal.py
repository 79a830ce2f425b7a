"""The lease book as JSON and back: a journal entry can be written, read after a restart and replayed.

Block payloads and queued command payloads must themselves be JSON-able; lists come back as tuples so a restored
book compares equal to the one that was saved. The owner's link watch is saved whole (its delivery window
included), so a restored book judges the link exactly as the saved one would have.
"""

from __future__ import annotations

from typing import Any

from vehicle.lease_terms import (
    BookState,
    ExecutionLease,
    ExpireReason,
    Holder,
    LeaseId,
    LeaseState,
    QueuedCommand,
    ServiceBlock,
)
from vehicle.link_watch import Delivery, LinkWatch, WatchConfig


def snapshot(book: BookState) -> dict[str, Any]:
    """A JSON-able picture of the book."""

    def lease(x: ExecutionLease) -> dict[str, Any]:
        return {
            "index": x.index, "holder": x.holder.name, "state": x.state.name, "claimed": x.claimed,
            "chain": x.chain, "newest_sub": list(x.newest_sub), "started_at": x.started_at,
            "block": None if x.block is None else {"payload": x.block.payload,
                                                   "halt_on_regain": x.block.halt_on_regain},
        }

    c = book.config
    return {
        "config": {"link_timeout": c.link_timeout, "regain_s": c.regain_s, "contact_gap": c.contact_gap,
                   "min_quality": c.min_quality, "rearm": c.rearm, "autogrant": c.autogrant,
                   "stale_take": c.stale_take},
        "epoch": book.epoch, "owner": book.owner, "owner_compid": book.owner_compid,
        "leases": [lease(x) for x in book.leases], "next_index": book.next_index, "chains": book.chains,
        "plan": [{"payload": b.payload, "halt_on_regain": b.halt_on_regain} for b in book.plan],
        "claims": [[s, lid.epoch, list(lid.path)] for s, lid in book.claims],
        "queue": [[q.lease.epoch, list(q.lease.path), q.sender, q.payload] for q in book.queue],
        "link": _link_snapshot(book.link),
        "last_reason": book.last_reason.name, "takeover_allowed": book.takeover_allowed,
        "last_epoch": book.last_epoch,
    }


def restored_fields(snap: dict[str, Any], watch: WatchConfig) -> dict[str, Any]:
    """Every field of the book but its configuration, from ``snapshot``'s picture (``watch``: the link watch's
    part of the restored configuration)."""

    def block(d: dict[str, Any] | None) -> ServiceBlock | None:
        return None if d is None else ServiceBlock(_freeze(d["payload"]), d["halt_on_regain"])

    leases = tuple(
        ExecutionLease(x["index"], Holder[x["holder"]], LeaseState[x["state"]], block(x["block"]),
                       x["claimed"], x["chain"], tuple(x["newest_sub"]), x["started_at"])
        for x in snap["leases"]
    )
    return {
        "epoch": snap["epoch"], "owner": snap["owner"], "owner_compid": snap["owner_compid"], "leases": leases,
        "next_index": snap["next_index"], "chains": snap["chains"],
        "plan": tuple(block(b) for b in snap["plan"]),
        "claims": tuple((s, LeaseId(e, tuple(p))) for s, e, p in snap["claims"]),
        "queue": tuple(QueuedCommand(LeaseId(e, tuple(p)), s, _freeze(pl)) for e, p, s, pl in snap["queue"]),
        "link": _link_restore(watch, snap["link"]), "last_reason": ExpireReason[snap["last_reason"]],
        "takeover_allowed": snap["takeover_allowed"], "last_epoch": snap["last_epoch"],
    }


def _link_snapshot(link: LinkWatch) -> dict[str, Any]:
    d = link.delivery
    return {"last_heard": link.last_heard, "contact_since": link.contact_since,
            "contact_packets": link.contact_packets, "lost": link.lost,
            "quality_heard": link.quality_heard, "low": link.low,
            "last_good": link.last_good,
            "delivery": {"arrivals": [list(a) for a in d.arrivals], "newest": d.newest, "last_t": d.last_t,
                         "repeats": d.repeats}}


def _link_restore(config: WatchConfig, snap: dict[str, Any]) -> LinkWatch:
    d = snap.get("delivery") or {}
    delivery = Delivery(tuple((float(a), int(u)) for a, u in d.get("arrivals", ())), d.get("newest"),
                        d.get("last_t"), d.get("repeats", 0))
    return LinkWatch(config=config, last_heard=snap["last_heard"], contact_since=snap["contact_since"],
                     contact_packets=snap.get("contact_packets", 0), lost=snap["lost"],
                     last_good=snap.get("last_good"), delivery=delivery, quality_heard=snap.get("quality_heard"),
                     low=snap.get("low", False))


def _freeze(value: Any) -> Any:
    """JSON lists back to tuples, so restored payloads compare equal to the originals."""
    if isinstance(value, list):
        return tuple(_freeze(v) for v in value)
    if isinstance(value, dict):
        return {k: _freeze(v) for k, v in value.items()}
    return value
