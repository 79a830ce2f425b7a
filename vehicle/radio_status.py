"""What a SiK-style telemetry radio's RADIO_STATUS tells the vehicle: the owner's signal strength at the robot
(docs/architecture.md §11.1 "Radio telemetry").

A SiK radio injects RADIO_STATUS (msgid 109; the older ArduPilot RADIO, 166, has the same fields) into the serial
stream toward the computer it is plugged into, about once a second, as system 51, component 68:

* ``rssi``: the *local* radio's received signal strength: how well this radio hears the radio at the far end;
* ``remrssi``: the *remote* radio's, as the far end last reported it over the air: how well the far end hears us;
* ``noise`` / ``remnoise`` the same for the noise floor; ``rxerrors``, ``fixed`` (corrected errors) and ``txbuf``
  (the local send buffer's free share, for flow control).

Each strength is a byte in SiK units: 0..254, dBm about value / 1.9 - 127 (``link.radio.rssi_to_radio_status`` is
the simulator's inverse of this), 255 meaning unknown.

Which one is the owner's signal at the vehicle: the radio the companion (or a native vehicle) reads is the
vehicle-side radio, plugged into the robot, and the far end is the ground radio at the owner's station. So
``rssi``, the local end, is the owner's signal as received on the robot, which is what the link map keeps per place
beside the owner's packet delivery; ``remrssi`` is the robot's signal at the owner's station (the downlink). The
channel is nearly reciprocal, so the two differ by a few dB, but only ``rssi`` is measured here. (A ground radio's
report relayed to the vehicle over a network would carry the two the other way round; both radios call themselves
51/68, so nothing in the frame tells them apart: a deployment puts the SiK radio on the vehicle's side.)

What it is used for, and what not: the RSSI goes on the link map (``LinkMap.rssi``: mean per cell) and on the crumbs
laid while it is fresh (their link tag "plus RSSI when known", §6). It never decides whether the link is lost or
regained: that stays the owner's packet delivery and silence (``vehicle.link_watch``), since a strong carrier says
nothing about whether the owner's packets get through (a busy channel, a jammer, a dead ground station behind a
live radio).

A report whose ``rssi`` is 255 (unknown), not an integer (a bool, a float, NaN, a string from a malformed decoder),
or outside 0..254 is ignored (``rssi_dbm`` is None), and the reader counts it: the companion keeps
``counters["radio_reports"]`` and ``counters["radio_ignored"]``, so an ignored report is never silent. A decoded
MAVLink frame never has an out-of-range byte, so such a value means a frame that is not what it claims. Pure: no
clock, no socket, no state.
"""

from __future__ import annotations

UNKNOWN = 255  # SiK's "no measure"
MAX_VALUE = 254
SCALE = 1.9  # SiK units per dB
OFFSET_DBM = -127.0  # dBm at value 0
KINDS = frozenset(("RADIO_STATUS", "RADIO"))  # the message names that carry a radio's report (109, 166)
STALE_S = 3.0  # s: a reported RSSI older than this is not known any more (SiK reports about once a second)


def value_to_dbm(value: object) -> float | None:
    """A SiK strength byte in dBm; None for 255 (unknown) or anything that is not an integer 0..254."""
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= MAX_VALUE:
        return None
    return value / SCALE + OFFSET_DBM


def rssi_dbm(m: object) -> float | None:
    """The owner's signal at the vehicle (the local ``rssi``, see the module docstring) of a RADIO_STATUS or RADIO
    message, in dBm; None when the report has none (unknown, malformed, or not a radio's report at all)."""
    get_type = getattr(m, "get_type", None)
    try:
        kind = get_type() if callable(get_type) else None
    except Exception:  # noqa: BLE001 - a malformed object is not a report
        return None
    if kind not in KINDS:
        return None
    return value_to_dbm(getattr(m, "rssi", None))

