"""Telemetry's shortcuts against the general path: the same frames, byte for byte, over a whole story."""

from __future__ import annotations

from tests.harness import Pair
from vehicle.app import State
from vehicle.services.telemetry import Telemetry


def story(pair: Pair) -> list[bytes]:
    """Control taken, a drive, a commanded return and the lease claimed back, a link outage and its regain, a
    hold, takeover allowed, a release: every key telemetry watches changes at least once, most ticks nothing
    does."""
    pair.take_control()
    gs = pair.gs
    gs.drive_velocity(1.0, 0.0)
    pair.step(6.0)
    gs.stop()
    pair.step(1.0)
    gs.rtl()
    pair.until(lambda: pair.vehicle.state() == State.AWAITING_CLAIM, 30, "the commanded return to end")
    gs.claim()
    pair.step(1.0)
    t0 = pair.t
    pair.lose = lambda sysid, t: t0 <= t < t0 + 4.0
    pair.step(8.0)
    gs.hold()
    pair.step(1.0)
    gs.acquire(allow_takeover=True)
    pair.step(1.5)
    gs.release()
    pair.step(2.0)
    return pair.heard


def test_the_on_change_watch_sends_what_checking_every_tick_sends(monkeypatch):
    """``Telemetry.tick`` and ``_on_change`` recompute the on-change keys only when a value they depend on
    changed; forcing the recomputation on every tick must not change one byte."""
    watched = story(Pair())
    tick = Telemetry.tick

    def every_tick(self, t):
        self._seen = (object(),) * len(self._seen)  # nothing matches: the keys are recomputed now
        self._keys_from = (object(),) * len(self._keys_from)
        tick(self, t)

    monkeypatch.setattr(Telemetry, "tick", every_tick)
    general = story(Pair())
    assert len(watched) > 500
    assert watched == general


def test_message_classes_take_the_defaults_of_the_send_methods():
    """The builders construct pymavlink's message objects and ``send`` them, as ``<name>_send`` does after
    ``<name>_encode``: the trailing arguments they leave out must default the same way (HEARTBEAT's
    mavlink_version has no default in the class: it is passed, with the send method's value)."""
    import inspect

    from link import dialect
    from link.wire import MAVLINK_VERSION
    from vehicle.services.telemetry import BUILDERS

    mav = dialect.load()
    for msgid in BUILDERS:
        if msgid not in mav.mavlink_map:
            continue  # CURRENT_MODE: sent as a message object of its own dialect either way
        cls = mav.mavlink_map[msgid]
        encode = getattr(mav.MAVLink, f"{cls.msgname.lower()}_encode")
        ours = {k: p.default for k, p in inspect.signature(cls.__init__).parameters.items() if k != "self"}
        theirs = {k: p.default for k, p in inspect.signature(encode).parameters.items() if k != "self"}
        if cls.msgname == "HEARTBEAT":
            assert theirs.pop("mavlink_version") == MAVLINK_VERSION
            assert ours.pop("mavlink_version") is inspect.Parameter.empty
        assert ours == theirs, cls.msgname
