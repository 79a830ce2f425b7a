"""The owner's link watch as timelines (PX4 failsafe_test style): time is advanced by hand and the trigger is
checked after each step. One story per rule of docs/architecture.md §3.5 and §6 "Where the return ends" about the link.
"""

from __future__ import annotations

import random

from hypothesis import given, settings
from hypothesis import strategies as st

from vehicle.lease import ExpireReason, Holder, LeaseBook, LeaseConfig
from vehicle.link_watch import EPS, GOOD_QUALITY, REGAIN_PACKETS, Delivery, LinkWatch, Trigger, WatchConfig

GCS = 255
RATE = 10.0  # packets/s, a ground station streaming teleop


class Station:
    """A sender with a MAVLink sequence number, feeding a watch as its packets arrive."""

    def __init__(self, watch: LinkWatch, seq: int = 0) -> None:
        self.watch = watch
        self.seq = seq
        self.triggers: list[tuple[float, Trigger]] = []

    def send(self, t: float, arrives: bool = True) -> None:
        if arrives:
            self.watch = self.watch.heard(t, self.seq)
        self.seq = (self.seq + 1) % 256

    def step(self, t: float) -> Trigger:
        self.watch, trig = self.watch.step(t)
        if trig is not Trigger.NONE:
            self.triggers.append((t, trig))
        return trig

    def run(self, t0: float, t1: float, arrives=lambda k, t: True, dt: float = 0.02) -> None:
        """50 Hz ticks from t0 to t1, a packet every 1/RATE s (``arrives(k, t)`` says whether packet k gets
        through)."""
        n0, n1 = round(t0 / dt), round(t1 / dt)
        every = round(1 / RATE / dt)
        for n in range(n0, n1):
            t = n * dt  # a product, not a sum: the watch must cope with 2.9999999999999964 as well
            if n % every == 0:
                self.send(t, arrives(n // every, t))
            self.step(t)


def cfg(**kw) -> WatchConfig:
    return WatchConfig(**{"timeout": 3.0, "regain_s": 1.0, "contact_gap": 1.5, "min_quality": 0.25, **kw})


def test_regain_comes_regain_s_after_the_link_is_back_however_long_the_outage():
    for outage in (4.0, 8.0, 30.0):
        st = Station(LinkWatch(cfg()))
        st.run(0.0, 10.0)
        st.run(10.0, 10.0 + outage, arrives=lambda k, t: False)  # packets sent but lost: the sequence advances
        back = 10.0 + outage
        st.run(back, back + 5.0)
        (lost_t, lost), (reg_t, reg) = st.triggers
        assert lost is Trigger.LOST and abs(lost_t - (10.0 - 0.1 + 3.0)) < 0.021
        assert reg is Trigger.REGAINED
        assert back + 1.0 - 1e-9 <= reg_t <= back + 1.0 + 0.021, (outage, reg_t)


def test_a_jump_of_more_than_128_sequence_numbers_is_an_outage_not_a_reorder():
    st = Station(LinkWatch(cfg()))
    st.run(0.0, 5.0)
    st.seq = (st.seq + 200) % 256  # 200 packets lost in a 4 s outage at 50 Hz
    st.run(5.0, 9.0, arrives=lambda k, t: False)
    st.run(9.0, 12.0)
    assert [trig for _, trig in st.triggers] == [Trigger.LOST, Trigger.REGAINED]
    assert st.triggers[1][0] <= 10.0 + 0.021


def test_contact_from_before_the_loss_never_counts_as_regained():
    """LNK_TIMEOUT below LNK_GOOD_S: the loss must not be 'regained' by the packet that came before it."""
    st = Station(LinkWatch(cfg(timeout=0.5, contact_gap=1.5)))
    st.run(0.0, 5.0)
    st.run(5.0, 5.8, arrives=lambda k, t: False)  # 0.8 s silent: lost after 0.5 s
    for n in range(290, 300):
        st.step(n * 0.02)
    assert [trig for _, trig in st.triggers] == [Trigger.LOST]
    st.run(5.8, 8.0)
    assert [trig for _, trig in st.triggers] == [Trigger.LOST, Trigger.REGAINED]
    assert 6.8 - 1e-9 <= st.triggers[1][0] <= 6.8 + 0.021


def test_lost_fires_on_the_tick_the_timeout_ends_whatever_the_clock_reads():
    """LNK_TIMEOUT after the last packet is a tick's deadline: the tick that reaches it fires LOST, never the one
    after, though tick times are floats (the runner's k / 50) whose differences are not exact (heard at 30.8 s,
    the tick at 33.8 s is 2.9999999999999964 s later)."""
    for k0 in range(0, 5000, 7):
        w = LinkWatch(cfg()).heard(k0 / 50, 0)
        fired = None
        for n in range(1, 200):
            w, trig = w.step((k0 + n) / 50)
            if trig is Trigger.LOST:
                fired = n
                break
        assert fired == 150, (k0 / 50, fired)  # 3.0 s of 20 ms ticks


def test_reordering_and_duplicates_are_not_loss():
    # 40 % of packets swapped with the next one, every packet duplicated: nothing is lost
    d = Delivery()
    seq = list(range(300))
    for k in range(0, 300, 5):  # swap pairs: 2 of every 5 packets out of order
        seq[k], seq[k + 1] = seq[k + 1], seq[k]
    for k, s in enumerate(seq):
        t = k * 0.1
        d = d.heard(s % 256, t, 3.0, 3.0)
        d = d.heard(s % 256, t + 0.01, 3.0, 3.0)
        # a packet overtaken by the next one is a hole only until it arrives
        assert d.ratio(t + 0.01, 1.0) >= GOOD_QUALITY, k
    assert d.ratio(29.9, 1.0) == 1.0
    w = LinkWatch(cfg())
    for k, s in enumerate(seq):
        w = w.heard(k * 0.1, s % 256).heard(k * 0.1 + 0.01, s % 256)
        assert w.good(k * 0.1 + 0.01) and w.contact_since == 0.0, k  # contact never broken


def test_duplicates_do_not_hide_loss():
    """Half the packets lost, each survivor duplicated and the copy arriving late: delivery is a half, not 1."""
    d = Delivery()
    sent = [k for k in range(1, 200, 2)]
    arrivals = [sent[0]] + [x for a, b in zip(sent[1:], sent, strict=False) for x in (a, b)]
    for n, s in enumerate(arrivals):
        d = d.heard(s % 256, n * 0.1, 3.0, 3.0)
    assert abs(d.ratio(len(arrivals) * 0.1, 3.0) - 0.5) < 0.1


def test_loss_is_measured_over_the_window():
    d = Delivery()
    for k in range(100):
        if k % 2:
            d = d.heard(k, k * 0.1, 3.0, 3.0)
    assert abs(d.ratio(9.9, 1.0) - 0.5) < 0.11
    w = LinkWatch(cfg())
    for k in range(100):
        if k % 2:
            w = w.heard(k * 0.1, k)
    assert not w.good(9.9)  # a link-good crumb needs a good delivery, not just a recent packet


def test_a_sender_that_never_advances_its_sequence_is_not_perfect():
    w = LinkWatch(cfg())
    for k in range(50):
        w = w.heard(k * 0.1, 7)
    assert w.quality(5.0) is None
    assert not w.good(5.0)


def test_marginal_delivery_counts_as_lost_after_the_timeout():
    """LNK_MIN_Q: one packet in eight gets through; the lucky ones keep the silence timer from firing."""
    st = Station(LinkWatch(cfg()))
    st.run(0.0, 10.0)
    st.run(10.0, 30.0, arrives=lambda k, t: k % 8 == 0)
    assert [trig for _, trig in st.triggers][:1] == [Trigger.LOST]
    assert st.triggers[0][0] <= 10.0 + 3.0 + 1.0  # within about a timeout of the delivery falling


def test_silence_only_when_min_quality_is_zero():
    st = Station(LinkWatch(cfg(min_quality=0.0)))
    st.run(0.0, 10.0)
    st.run(10.0, 30.0, arrives=lambda k, t: k % 8 == 0)
    assert st.triggers == []


def test_lease_book_consumes_the_trigger():
    book = LeaseBook(config=LeaseConfig(link_timeout=0.5, contact_gap=1.5)).acquire(GCS, 190, 0.0).book
    t, seq = 0.0, 0
    events = []
    for n in range(1, 400):
        t = n * 0.02
        if n % 5 == 0 and not 100 <= n < 140:  # silent from 2.0 s to 2.8 s
            book = book.heard(GCS, t, seq)
        seq += n % 5 == 0
        out = book.tick(t)
        book = out.book
        events += [(e.t, e.reason) for e in out.events]
    reasons = [r for _, r in events]
    assert reasons == [ExpireReason.COMMS_LOST, ExpireReason.LINK_REGAINED]
    assert events[1][0] - events[0][0] >= 1.0 - 1e-9
    assert book.current.holder is Holder.OPERATOR and not book.current.claimed


def test_two_lucky_packets_are_not_a_regained_link():
    """After a loss, two heartbeats a second apart do not make LINK_REGAINED; a stream for LNK_REGAIN_S does."""
    st = Station(LinkWatch(cfg()))
    st.run(0.0, 5.0)
    st.run(5.0, 10.0, arrives=lambda k, t: False)
    assert [trig for _, trig in st.triggers] == [Trigger.LOST]
    st.send(10.0)
    st.step(10.0)
    st.send(11.0)
    for n in range(550, 600):
        st.step(n * 0.02)
    assert [trig for _, trig in st.triggers] == [Trigger.LOST]
    st.run(12.0, 14.0)
    assert [trig for _, trig in st.triggers] == [Trigger.LOST, Trigger.REGAINED]


def _ratio_by_definition(arrivals, t: float, window: float) -> float:
    """The share of packets sent in the window that arrived, spelled out (reference for ``Delivery.ratio``)."""
    since = t - window - EPS
    inside = [u for ta, u in arrivals if ta > since]
    if not inside:
        return 0.0
    before = [u for ta, u in arrivals if ta <= since]
    first = max(before) if before else min(inside) - 1
    sent = max(inside) - first
    return min(1.0, len(inside) / sent) if sent > 0 else 1.0


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(st.floats(0, 10), st.integers(0, 400)), max_size=40), st.floats(0, 12), st.floats(0.1, 4))
def test_delivery_ratio_is_its_definition(arrivals, t, window):
    arrivals = tuple(sorted(arrivals, key=lambda a: a[1]))
    d = Delivery(arrivals, arrivals[-1][1] if arrivals else None, arrivals[-1][0] if arrivals else None, 0)
    want = None if not arrivals else _ratio_by_definition(arrivals, t, window)
    assert d.ratio(t, window) == want


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(st.floats(0, 10), st.integers(0, 400)), max_size=40), st.floats(0, 12),
       st.floats(0.1, 4), st.floats(0.1, 4))
def test_two_windows_in_one_pass_are_each_its_ratio(arrivals, t, short, long):
    arrivals = tuple(sorted(arrivals, key=lambda a: a[1]))
    d = Delivery(arrivals, arrivals[-1][1] if arrivals else None, arrivals[-1][0] if arrivals else None, 0)
    want = (None, None) if not arrivals else (_ratio_by_definition(arrivals, t, short),
                                              _ratio_by_definition(arrivals, t, long))
    assert d.ratios(t, short, long) == want


@settings(max_examples=500, deadline=None)
@given(st.lists(st.tuples(st.floats(0, 10), st.integers(0, 400)), max_size=40, unique_by=lambda a: a[1]),
       st.floats(0, 60))
def test_the_cheap_bound_never_hides_a_wrapped_sequence(arrivals, silence):
    """A window restarts after a silence of half a sequence space at the sender's rate; the quick look at the
    first and last arrival must give the same answer as the full interval, whatever the arrival order in time."""
    arrivals = tuple(sorted(arrivals, key=lambda a: a[1]))
    d = Delivery(arrivals, arrivals[-1][1] if arrivals else None, arrivals[-1][0] if arrivals else None, 0)
    interval = d.interval()
    assert d._may_have_wrapped(silence) == (interval is not None and silence >= 128 * interval)


def test_ratios_by_bisection_match_the_walk_over_every_arrival():
    """Arrival times in sequence order take the bisection; it must give exactly what the walk gives, window
    edges falling on an arrival (and on several arrivals of one tick) included. Out-of-order times take the walk."""
    rng = random.Random(5)
    bisected = 0
    for _ in range(3000):
        n = rng.randint(0, 40)
        useq = sorted(rng.sample(range(1000), n))
        times = sorted(round(rng.choice((0.02, 0.04, 0.1)) * rng.randint(0, 200), 9) for _ in range(n))
        ordered = rng.random() < 0.8
        if not ordered and n > 1:
            i, j = rng.sample(range(n), 2)
            times[i], times[j] = times[j], times[i]
        d = Delivery(tuple(zip(times, useq, strict=True)), useq[-1] if useq else 0, times[-1] if times else 0.0, 0)
        short, long = rng.choice(((1.0, 3.0), (0.5, 0.5), (3.0, 1.0)))
        t = (times[rng.randrange(n)] + short + EPS) if n and rng.random() < 0.5 else rng.uniform(0.0, 25.0)
        assert d.ratios(t, short, long) == d._ratios_scan(t, short, long)
        bisected += times == sorted(times)
    assert bisected > 2000


def test_regaining_while_contact_is_back_but_the_regain_not_yet_due():
    """What a return arriving at its target asks before going on: a regain on its way is waited for there."""
    w = LinkWatch(cfg())
    for n in range(50):  # 10 Hz for 5 s
        w = w.heard(n * 0.1, n)
        w, _ = w.step(n * 0.1)
    w, trig = w.step(8.0)  # silent past the timeout
    assert trig is Trigger.LOST and not w.regaining(8.0)
    w = w.heard(8.0, 80)
    w, _ = w.step(8.0)
    assert w.lost and w.regaining(8.1)  # heard again, LINK_REGAINED not yet due
    assert not w.regaining(8.0 + 1.5 + 0.1)  # the contact broke off again: nothing on its way
    for n in range(81, 95):
        w = w.heard(n * 0.1, n)
        w, trig = w.step(n * 0.1)
        if trig is Trigger.REGAINED:
            break
    assert trig is Trigger.REGAINED and not w.regaining(w.last_heard)


def test_the_approach_holds_while_heard_well_not_after_a_stray_packet():
    """What holds a return at its approach speed (issue 38): a packet heard again after a loss, only until the next
    shows the owner's stream arriving one packet in five; after a silence, the stream coming back whole, from its
    first packet, and from its third to the block's end (the regain's window filling). Where the delivery rises
    gradually instead, the window fills and the regain comes together."""
    st = Station(LinkWatch(cfg()))
    st.run(0.0, 5.0)
    st.run(5.0, 10.0, arrives=lambda k, t: False)
    st.send(10.0)  # a stray packet
    st.step(10.0)
    assert st.watch.heard_again(10.0) and 0 < st.watch.heard_well(10.0) < REGAIN_PACKETS  # not yet begun
    well = []
    begun = []
    for n in range(501, 1000):
        t = n * 0.02
        if n % 5 == 0:
            st.send(t, t >= 18.0 - 1e-9 or (t < 16.0 and (n // 5) % 5 == 0))
        st.step(t)
        if st.watch.heard_well(t) >= REGAIN_PACKETS:
            begun.append(t)
        if st.watch.heard_well(t):
            well.append(t)
    assert not [t for t in well if 10.5 - 1e-9 <= t < 18.0]  # the next packet showed the gaps
    assert begun and 18.2 - 1e-9 <= begun[0] <= 18.2 + 0.021, begun[:3]  # 18.0, 18.1, 18.2: three of three


def test_one_lost_packet_at_the_fringe_does_not_restart_the_regain():
    """A 4 Hz stream heard again after an outage, one packet of it lost half a second in: LINK_REGAINED comes
    LNK_REGAIN_S after the link came back, as it would have without the loss (delivery over the window 4 of 5),
    not LNK_REGAIN_S after the lost packet (issue 38: a run of good packets restarted at every loss)."""
    def run(lose: set[int]) -> float:
        st = Station(LinkWatch(cfg()))
        for n in range(0, 1000):  # 4 Hz for 5 s, silent until 10 s, then 4 Hz again
            t = n * 0.02
            if n % 12 == 0 and not 250 <= n < 500:
                k = n // 12
                st.send(t, k not in lose)
            elif n % 12 == 0:
                st.send(t, False)
            st.step(t)
        assert [trig for _, trig in st.triggers] == [Trigger.LOST, Trigger.REGAINED]
        return st.triggers[1][0]

    first_back = 504 * 0.02  # the first packet after the outage (n = 504, k = 42)
    clean = run(set())
    assert first_back + 1.0 - 1e-9 <= clean <= first_back + 1.0 + 0.021
    assert run({44}) == clean  # one lost half a second in (4 of 5 over the window: 0.8)


def test_a_regain_needs_the_regain_share_over_the_window():
    """Two packets of every three (no second of them reaches REGAIN_QUALITY) never make LINK_REGAINED, however
    long they go on; nine of ten do, LNK_REGAIN_S after they began."""
    st = Station(LinkWatch(cfg()))
    st.run(0.0, 5.0)
    st.run(5.0, 10.0, arrives=lambda k, t: False)
    st.run(10.0, 30.0, arrives=lambda k, t: k % 3 != 0)
    assert [trig for _, trig in st.triggers] == [Trigger.LOST]
    st.run(30.0, 35.0, arrives=lambda k, t: k % 10 != 0)
    assert [trig for _, trig in st.triggers] == [Trigger.LOST, Trigger.REGAINED]
    assert st.triggers[1][0] <= 31.0 + 0.1


@settings(max_examples=150, deadline=None)
@given(timeout=st.floats(0.5, 120.0), regain_s=st.floats(0.0, 10.0), contact_gap=st.floats(0.1, 10.0),
       min_quality=st.floats(0.0, 0.9), interval=st.sampled_from([0.02, 0.04, 0.1, 0.2, 0.25, 0.5, 1.0]),
       every=st.integers(0, 20), outage=st.floats(0.0, 3.0))
def test_no_parameters_make_lost_and_regained_alternate(timeout, regain_s, contact_gap, min_quality, interval,
                                                        every, outage):
    """Any valid LNK_TIMEOUT, LNK_REGAIN_S, LNK_GOOD_S and LNK_MIN_Q; a steady sender whose silences stay shorter
    than LNK_TIMEOUT (a link that, by the contract's own measure, is not silent), losing every ``every``-th
    packet once it is back (0: none): after an outage the watch says LOST once, and REGAINED at most once, and
    never LOST again while the link stays as it is."""
    every = 0 if every == 1 else every  # (losing every packet is the outage, not a link)
    longest = interval * (2 if every else 1)
    if longest >= timeout - 1e-6:
        return  # the sender's own silences are LNK_TIMEOUT long: lost by definition
    watch = LinkWatch(WatchConfig(timeout=timeout, regain_s=regain_s, contact_gap=contact_gap,
                                  min_quality=min_quality))
    triggers: list[Trigger] = []
    dt = 0.02
    per = round(interval / dt)
    down_from = round(5.0 / dt)
    back_at = down_from + round((timeout + outage + 0.5) / dt)
    end = back_at + round((regain_s + 2 * timeout + 10.0) / dt)
    step = max(1, min(per, 5))  # a tick every 0.1 s at most between packets (the deadlines hold within it)
    seq = 0
    for n in range(0, end, step) if step == per else range(0, end):
        t = n * dt
        if n % per == 0:
            k = n // per
            if n < down_from or (n >= back_at and not (every and k % every == 0)):
                watch = watch.heard(t, seq)
            seq = (seq + 1) % 256
        watch, trig = watch.step(t)
        if trig is not Trigger.NONE:
            triggers.append(trig)
    assert triggers[:1] == [Trigger.LOST] and triggers in ([Trigger.LOST], [Trigger.LOST, Trigger.REGAINED]), \
        triggers
