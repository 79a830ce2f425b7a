"""Telemetry's message builders against pymavlink's own send methods: the same defaults."""

from __future__ import annotations


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
