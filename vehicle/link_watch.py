"""The owner's link, watched in one place: is it up, is it good, has it just been lost or regained
(docs/architecture.md §3.5, §6).

Why a value of its own (STYLE §2, Spot's ``LeaseKeepAlive`` beside its ``LeaseWallet``): the lease ledger decides
*what happens* on COMMS_LOST and LINK_REGAINED; this module decides *whether* they happened. Both were spread over
the lease book, the vehicle loop and a link-quality helper, and each place had its own idea of "good".

Two measurements, both pure functions of the packets heard and the time passed in:

* **Delivery** (``Delivery``): the share of the owner's packets that arrive, from MAVLink sequence numbers, kept
  like a receiver window (RFC 3550 style): every distinct packet of the last ``window`` seconds, unwrapped into a
  monotonic sequence space. A duplicate is counted once, a reordered packet fills its hole instead of counting as
  a loss, and a sender whose sequence number never advances is *unmeasurable* (``ratio`` None), not perfect. A
  gap in uint8 sequence space says nothing about how many packets an outage swallowed (a jump of more than 128 is
  ambiguous, and even a small one may have wrapped), so after a silence of LNK_TIMEOUT (or one long enough to
  wrap at the sender's rate) the window restarts: the outage is already measured by time, and counting it again
  as loss would only delay the regain.
* **Contact** (``LinkWatch``): when the owner was last heard, since when it has been heard without a silence
  longer than LNK_GOOD_S, and whether the link is lost. ``step(t)`` says LOST (silent for LNK_TIMEOUT, or delivery
  below LNK_MIN_Q over LNK_TIMEOUT) or REGAINED: contact that began *after* the loss has lasted LNK_REGAIN_S and the
  owner's delivery over the last LNK_REGAIN_S reaches ``REGAIN_QUALITY`` (DESIGN §6.2). A window, not a run of good
  packets: one packet lost at the fringe of coverage lowers the share a little instead of restarting the count,
  so a one-tick change no longer moves a regain by seconds (issue 38; docs/evidence.md, "The measurements behind
  the vehicle's code"). REGAINED also needs the link to pass the very tests LOST applies (heard within
  LNK_TIMEOUT, delivery over LNK_TIMEOUT not below LNK_MIN_Q): a regain that the next tick would call lost again
  is not one.

``REGAIN_QUALITY`` is the one number behind both the regain and the link map (``vehicle.linkmap``): the map vouches
for a place only where its lower bound on delivery meets it, so a return sent to a place the map vouches for is sent
where a regain can happen.

Deadlines are compared with a tolerance of ``EPS``: in floating point 33.8 - 30.8 is 2.9999999999999964, and a tick
must not fire one period late because of it.
"""

from __future__ import annotations

import enum
from bisect import bisect_right
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

from link.parameters import default

if TYPE_CHECKING:
    from vehicle.params import Params

EPS = 1e-6  # s: deadline tolerance (far below the 20 ms tick, far above float error)
REGAIN_QUALITY = 0.8  # the owner's delivery over LNK_REGAIN_S at which a lost link is regained; the link map
# vouches for a place only where its lower bound meets it (one number, here, for both)
GOOD_QUALITY = REGAIN_QUALITY  # a crumb laid with at least this delivery is link-good (the same standard)
SEQ_SPACE = 256  # MAVLink's uint8 sequence number
MAX_WINDOW_PACKETS = 1024  # memory bound of the receiver window (a fast sender shortens the window it covers)
STUCK_REPEATS = 3  # arrivals of one sequence number, none advancing, after which a sender is unmeasurable
REGAIN_PACKETS = 3  # packets a regain window needs at least: two lucky heartbeats a second apart are not a link
# (on a working link a ground station's stream brings ten times as many within LNK_REGAIN_S)


class Trigger(enum.Enum):
    """What ``LinkWatch.step`` found."""

    NONE = "none"
    LOST = "lost"
    REGAINED = "regained"


@dataclass(frozen=True)
class WatchConfig:
    """The LNK_* parameters the watch depends on; defaults from the parameter table."""

    timeout: float = default("LNK_TIMEOUT")
    regain_s: float = default("LNK_REGAIN_S")
    contact_gap: float = default("LNK_GOOD_S")  # the longest silence that still counts as continuous contact
    min_quality: float = default("LNK_MIN_Q")  # 0 = silence only
    window: float = 1.0  # s: the delivery estimate behind "good" covers about this long

    @classmethod
    def from_params(cls, params: Params) -> WatchConfig:
        return cls(timeout=params["LNK_TIMEOUT"], regain_s=params["LNK_REGAIN_S"],
                   contact_gap=params["LNK_GOOD_S"], min_quality=params["LNK_MIN_Q"])


@dataclass(frozen=True)
class Delivery:
    """A receiver window over one sender's sequence numbers: which distinct packets arrived, and when."""

    arrivals: tuple[tuple[float, int], ...] = ()  # (time, unwrapped seq) of distinct packets, oldest first
    newest: int | None = None  # highest unwrapped sequence number seen
    last_t: float | None = None  # time of the last arrival (duplicates included)
    repeats: int = 0  # arrivals in a row that did not advance the sequence number

    def heard(self, seq: int, t: float, horizon: float, outage: float) -> Delivery:
        """One packet with sequence number ``seq`` at ``t``; the window keeps ``horizon`` seconds. After a silence
        of ``outage`` seconds, or one long enough for the sequence number to have wrapped at the sender's rate,
        the window restarts: the gap no longer says how many packets were lost."""
        seq %= SEQ_SPACE
        if self.newest is None or self.last_t is None:
            return Delivery(((t, seq),), seq, t, 0)
        silence = t - self.last_t
        if silence >= outage - EPS or self._may_have_wrapped(silence):
            return Delivery(((t, seq),), seq, t, 0)
        d = (seq - self.newest) % SEQ_SPACE
        if d == 0:
            return replace(self, last_t=t, repeats=self.repeats + 1)
        if d < SEQ_SPACE // 2:
            u = self.newest + d
            return Delivery(_trim((*self.arrivals, (t, u)), t - horizon), u, t, 0)
        u = self.newest - (SEQ_SPACE - d)  # behind the newest: a late packet or a duplicate of one
        first_t, first_u = self.arrivals[0]
        if any(a == u for _, a in self.arrivals) or (u < first_u and first_t <= t - horizon):
            return replace(self, last_t=t)  # a duplicate, or older than the window remembers
        arrivals = tuple(sorted((*self.arrivals, (t, u)), key=lambda a: a[1]))
        return replace(self, arrivals=_trim(arrivals, t - horizon), last_t=t)

    def _may_have_wrapped(self, silence: float) -> bool:
        """Whether the sender, at its rate over the window (``interval``), may have sent half a sequence space
        during ``silence``.

        ``interval`` takes the span of all arrival times, a pass over the window; the span between the first and
        the last arrival never exceeds it, so when even that span says the silence is too short the pass is
        skipped. It nearly always is: on a live link the silence is one packet period, and this runs every packet.
        """
        a = self.arrivals
        if len(a) < 2:
            return False
        span_u = a[-1][1] - a[0][1]
        if span_u <= 0 or silence < (SEQ_SPACE // 2) * (abs(a[-1][0] - a[0][0]) / span_u):
            return False
        interval = self.interval()
        return interval is not None and silence >= (SEQ_SPACE // 2) * interval

    def interval(self) -> float | None:
        """The sender's mean time between packets over the window (None until it can be told)."""
        a = self.arrivals
        if len(a) < 2:
            return None
        times = [x for x, _ in a]
        span_t = max(times) - min(times)
        span_u = a[-1][1] - a[0][1]
        return span_t / span_u if span_t > 0 and span_u > 0 else None

    def share_since(self, t: float, window: float, since: float) -> tuple[float | None, int]:
        """The delivery over the last ``window`` seconds and the packets in it, charging no packet sent before
        ``since`` (the first packet of a contact: what a silence before it swallowed is not this contact's loss)."""
        if self.newest is None or self.repeats >= STUCK_REPEATS:
            return None, 0
        start = max(t - window, since) - EPS
        inside, lo, hi, before = 0, 0, 0, None
        for ta, u in self.arrivals:
            if ta > start:
                lo = u if not inside else min(lo, u)
                hi = max(hi, u)
                inside += 1
            elif ta >= since - EPS:
                before = u if before is None else max(before, u)
        return _share(inside, lo, hi, before), inside

    def covers(self, t: float, window: float) -> bool:
        """Whether the window reaches ``window`` seconds back from ``t`` (a ratio over it is a full measure)."""
        return bool(self.arrivals) and self.arrivals[0][0] <= t - window + EPS

    def count(self, t: float, window: float) -> int:
        """Distinct packets that arrived in the last ``window`` seconds."""
        since = t - window - EPS
        return sum(1 for ta, _ in self.arrivals if ta > since)

    def ratio(self, t: float, window: float) -> float | None:
        """Share of the packets sent in the last ``window`` seconds that arrived; None when it cannot be told
        (nothing heard yet, or a sender that never advances its sequence number)."""
        return self.ratios(t, window, window)[0]

    def ratios(self, t: float, short: float, long: float) -> tuple[float | None, float | None]:
        """``ratio`` over two windows in one pass: every packet from the owner measures both (the delivery behind
        "good" and the one LNK_MIN_Q judges), and two passes over the window were the link watch's largest cost.

        The arrivals are in sequence order, so inside a window the first one has the lowest sequence number and
        the last one the highest, and the last one before it the highest before it (the reference for what was
        sent since)."""
        if self.newest is None or self.repeats >= STUCK_REPEATS:
            return None, None
        arrivals = self.arrivals
        times = [ta for ta, _ in arrivals]
        if times != sorted(times):
            return self._ratios_scan(t, short, long)  # a late packet: arrival times out of sequence order
        # (every packet in order, the usual case: the arrivals inside a window are a tail of the list, found by
        # bisection instead of a walk over every arrival; ``_ratios_scan`` is the same measure for any order)
        return (_share_from(arrivals, bisect_right(times, t - short - EPS)),
                _share_from(arrivals, bisect_right(times, t - long - EPS)))

    def _ratios_scan(self, t: float, short: float, long: float) -> tuple[float, float]:
        """``ratios`` by one walk over the arrivals, whatever the order of their times."""
        short_since, long_since = t - short - EPS, t - long - EPS
        short_in = short_lo = short_hi = long_in = long_lo = long_hi = 0
        short_before: int | None = None
        long_before: int | None = None
        for ta, u in self.arrivals:
            if ta > short_since:
                if not short_in:
                    short_lo = u
                short_hi = u
                short_in += 1
            else:
                short_before = u
            if ta > long_since:
                if not long_in:
                    long_lo = u
                long_hi = u
                long_in += 1
            else:
                long_before = u
        return (_share(short_in, short_lo, short_hi, short_before),
                _share(long_in, long_lo, long_hi, long_before))


def _share_from(arrivals: tuple[tuple[float, int], ...], k: int) -> float:
    """``_share`` of a window holding ``arrivals[k:]``, after ``arrivals[k - 1]`` (arrival times in order)."""
    n = len(arrivals)
    if k >= n:
        return 0.0
    return _share(n - k, arrivals[k][1], arrivals[-1][1], arrivals[k - 1][1] if k else None)


def _share(inside: int, lo: int, hi: int, before: int | None) -> float:
    """Arrived over sent in a window: ``inside`` arrivals with sequence numbers ``lo``..``hi``, after ``before``."""
    if not inside:
        return 0.0
    first = before if before is not None else lo - 1
    sent = hi - first
    return min(1.0, inside / sent) if sent > 0 else 1.0


def _trim(arrivals: tuple[tuple[float, int], ...], since: float) -> tuple[tuple[float, int], ...]:
    """Drop arrivals older than ``since`` except the newest of them (the reference for what was sent since)."""
    k = 0
    while k + 1 < len(arrivals) and arrivals[k + 1][0] <= since:
        k += 1
    k = max(k, len(arrivals) - MAX_WINDOW_PACKETS)
    return arrivals[k:]


@dataclass(frozen=True)
class LinkWatch:
    """The owner's link as the vehicle knows it. Immutable; ``heard`` and ``step`` return new values."""

    config: WatchConfig = field(default_factory=WatchConfig)
    last_heard: float | None = None
    contact_since: float | None = None  # first packet of the current contact (no silence over LNK_GOOD_S; after
    # any loss: contact from before it never counts toward a regain)
    lost: bool = False  # LOST fired and REGAINED has not yet
    last_good: float | None = None  # the last packet heard with a good delivery (settles the crumbs' link tags)
    delivery: Delivery = field(default_factory=Delivery)
    # measured when the last packet came (between packets only silence changes, and the timeout measures that):
    # the 50 Hz tick reads two values instead of walking the window
    quality_heard: float | None = None  # delivery over ``window``
    low: bool = False  # delivery over a full LNK_TIMEOUT below LNK_MIN_Q

    # ----- inputs ------------------------------------------------------------------------------------------
    def heard(self, t: float, seq: int | None = None) -> LinkWatch:
        """A packet from the owner at ``t``. Without ``seq`` (a transport with no sequence numbers) the packet is
        taken as good; with it, the delivery it measures decides the crumbs' tag and the regain. A poor packet
        does not break contact: the regain window weighs it (a silence longer than LNK_GOOD_S does)."""
        cfg = self.config
        delivery, q, low = self.delivery, self.quality_heard, self.low
        if seq is not None:
            delivery = delivery.heard(seq, t, max(cfg.window, cfg.timeout, cfg.regain_s), cfg.timeout)
            q, q_timeout = delivery.ratios(t, cfg.window, cfg.timeout)
            low = _low(delivery, t, cfg, q_timeout)
        unbroken = (self.contact_since is not None and self.last_heard is not None
                    and t - self.last_heard <= cfg.contact_gap + EPS)
        good = seq is None or _good(q)
        return replace(self, last_heard=t, contact_since=self.contact_since if unbroken else t,
                       last_good=t if good else self.last_good, delivery=delivery, quality_heard=q, low=low)

    def step(self, t: float) -> tuple[LinkWatch, Trigger]:
        """Evaluate the deadlines at ``t``: LOST, REGAINED or nothing."""
        last = self.last_heard
        if last is None:
            return self, Trigger.NONE
        if not self.lost:
            if t - last >= self.config.timeout - EPS or self.low:
                # contact from before the loss never counts toward the regain
                return replace(self, lost=True, contact_since=None), Trigger.LOST
            return self, Trigger.NONE
        if self._regained(t):
            # the contact that counts from now on began where the window that proved the regain begins (a lucky
            # packet before it, at the fringe, was not the link coming back)
            since = self.contact_since
            assert since is not None
            return replace(self, lost=False, contact_since=t - self._regain_window(t, since)), Trigger.REGAINED
        return self, Trigger.NONE

    def _regained(self, t: float) -> bool:
        """Lost, and since: contact for LNK_REGAIN_S, still alive (heard within LNK_GOOD_S and LNK_TIMEOUT, not
        low), whose delivery over the regain window (``regain_delivery``) reaches REGAIN_QUALITY."""
        cfg = self.config
        since, last = self.contact_since, self.last_heard
        if since is None or last is None or t - since < cfg.regain_s - EPS:
            return False
        age = t - last
        if age > cfg.contact_gap + EPS or age >= cfg.timeout - EPS or self.low:
            return False
        if self.delivery.newest is None:
            return True  # no sequence numbers: unbroken contact is the measure
        q, packets = self.regain_delivery(t)
        return (packets >= REGAIN_PACKETS and q is not None and q >= REGAIN_QUALITY - EPS
                and self._clears_min_quality(t))

    def _clears_min_quality(self, t: float) -> bool:
        """The delivery over the last LNK_TIMEOUT (what of it the window holds) clears LNK_MIN_Q by two packets (by
        what it can spare, in a window of fewer than three).
        Why two: as a window slides over a steady link, the packets lost inside it change by one either way, so a
        delivery that clears the minimum by less may fall below it a moment later, and LOST would follow the
        regain on a link that did not change (the property ``test_no_parameters_make_lost_and_regained_alternate``
        found it: LNK_MIN_Q 0.75, one packet in four lost)."""
        min_q = self.config.min_quality
        if min_q <= 0:
            return True
        timeout = self.config.timeout
        at = self.last_heard if self.last_heard is not None else t  # judged when the last packet came, as ``low``
        q = self.delivery.ratio(at, timeout)
        inside = self.delivery.count(at, timeout)
        if q is None or q <= 0 or inside < 1:
            return False
        spare = min(2, inside - 1)  # (a window of one or two packets spares what it can: a 1 Hz owner, LNK_TIMEOUT 1.5)
        return q * (inside - spare) / inside >= min_q - EPS

    def regain_delivery(self, t: float) -> tuple[float | None, int]:
        """The owner's delivery over the regain window at ``t`` and the packets in it. The window is the last
        LNK_REGAIN_S (at least ``window``, so a zero LNK_REGAIN_S still measures a rate), stretched back to hold
        REGAIN_PACKETS packets when the owner sends slower than that (a ground station idling at its 1 Hz
        heartbeat), and never reaching back before the contact began (after a loss: before the loss)."""
        since = self.contact_since
        if since is None:
            return None, 0
        w = self._regain_window(t, since)
        return self.delivery.ratio(t, w), self.delivery.count(t, w)

    def _regain_window(self, t: float, since: float) -> float:
        w = max(self.config.regain_s, self.config.window)
        arrivals = self.delivery.arrivals
        if len(arrivals) >= REGAIN_PACKETS:
            w = max(w, t - min(ta for ta, _ in arrivals[-REGAIN_PACKETS:]))
        return max(0.0, min(t - since, w))

    def regaining(self, t: float) -> bool:
        """Lost, but the owner is heard well again at ``t`` (delivery over ``window`` good): LINK_REGAINED is
        due once the contact has lasted LNK_REGAIN_S. A return arriving at its target waits for it there."""
        return self.heard_again(t) and (self.delivery.newest is None or _good(self.quality_heard))

    def heard_again(self, t: float) -> bool:
        """Lost, and the owner heard again since, within LNK_GOOD_S of ``t``."""
        return (self.lost and self.contact_since is not None and self.last_heard is not None
                and t - self.last_heard <= self.config.contact_gap + EPS)

    def heard_well(self, t: float) -> int:
        """Lost, and heard again at ``t`` as if the link were back: the packets in the regain window when the owner
        was heard within LNK_GOOD_S and its delivery since the contact began reaches REGAIN_QUALITY, however few
        they are so far; 0 otherwise. A return slows to its approach speed (RTL_APPROACH_SPD) while this is not 0,
        so that the regain's window and the braking end close to where the link came back: from the first packet
        heard again at a hard edge, but not for long after a stray packet at the fringe of a gradual fade, whose
        next packets show the gaps between them (one packet in five: 2 of 6). From REGAIN_PACKETS on the regain's
        window is filling, and a return keeps its approach speed to its end even through the gaps a fringe still
        brings. Why both, measured: docs/evidence.md, "The return service"."""
        q, packets = self._contact_delivery(t)
        return packets if q is not None and q >= REGAIN_QUALITY - EPS else 0

    def _contact_delivery(self, t: float) -> tuple[float | None, int]:
        """Lost and heard again: the owner's delivery over the regain window, charging nothing lost in the silence
        before the contact began (a stray packet a second before the stream comes back whole would otherwise hold
        the approach off until the regain itself), and the packets in it. Not heard again: (None, 0)."""
        if not self.heard_again(t):
            return None, 0
        if self.delivery.newest is None:
            return 1.0, REGAIN_PACKETS  # no sequence numbers: contact is the measure, as for the regain itself
        since = self.contact_since
        assert since is not None  # heard again
        return self.delivery.share_since(t, max(self.config.regain_s, self.config.window), since)

    def with_config(self, config: WatchConfig) -> LinkWatch:
        t = self.last_heard
        low = self.low if t is None else _low(self.delivery, t, config, self.delivery.ratio(t, config.timeout))
        return replace(self, config=config, low=low)

    # ----- queries -----------------------------------------------------------------------------------------
    def age(self, t: float) -> float | None:
        return None if self.last_heard is None else t - self.last_heard

    def quality(self, t: float) -> float | None:
        """The owner's packet delivery over the last ``window`` seconds (None: not measurable)."""
        return self.delivery.ratio(t, self.config.window)

    def good(self, t: float) -> bool:
        """The link tag of a crumb laid now: the owner heard within LNK_GOOD_S, with a good measured delivery
        (or no sequence numbers to measure it by)."""
        age = self.age(t)
        if age is None or age > self.config.contact_gap + EPS:
            return False
        return self.delivery.newest is None or _good(self.quality_heard)


def _low(delivery: Delivery, t: float, cfg: WatchConfig, q_timeout: float | None) -> bool:
    """LNK_MIN_Q: the owner's delivery over the last LNK_TIMEOUT (a full window of it, ``q_timeout`` =
    ``delivery.ratio(t, cfg.timeout)``) is below the minimum. Lucky packets reset the silence timer; they do not
    lift the delivery over a whole timeout."""
    if cfg.min_quality <= 0 or not delivery.covers(t, cfg.timeout):
        return False
    return q_timeout is not None and q_timeout < cfg.min_quality - EPS


def _good(q: float | None) -> bool:
    return q is not None and q >= GOOD_QUALITY - EPS
