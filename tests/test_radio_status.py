"""A SiK-style telemetry radio's RADIO_STATUS on the companion's ground side (docs/architecture.md §11.1 "Radio
telemetry"): decoded by ``vehicle.radio_status``, its RSSI on the companion's link map and crumbs; unknown and
malformed reports counted and ignored, never a crash."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import ardupilotmega as apm

from link.proxy import RADIO_COMPID, RADIO_SYSID, RadioReport
from link.radio import LinkState, rssi_to_radio_status
from link.signing import Key
from tests.companion_rig import FakeAutopilot, Rig
from vehicle.radio_status import STALE_S, UNKNOWN, rssi_dbm, value_to_dbm
from vehicle.trail import Trail


def booted(**kw) -> Rig:
    rig = Rig(**kw)
    assert rig.run(5, lambda: rig.companion.vehicle is not None), "the companion never booted"
    return rig


def parsed(frame: bytes):
    p = apm.MAVLink(None, 0, 0)
    p.robust_parsing = True
    (m,) = p.parse_buffer(frame)
    return m


class Radio:
    """The vehicle-side SiK radio: RADIO_STATUS frames as it injects them (sysid 51, compid 68)."""

    def __init__(self) -> None:
        self.mav = apm.MAVLink(None, RADIO_SYSID, RADIO_COMPID)

    def status(self, rssi: int, remrssi: int | None = None, noise: int = 30) -> bytes:
        remrssi = rssi if remrssi is None else remrssi
        return bytes(self.mav.radio_status_encode(rssi, remrssi, 100, noise, noise, 0, 0).pack(self.mav))


# ----- decoding -------------------------------------------------------------------------------------------------
def test_sik_units_become_dbm_and_unknown_or_garbage_becomes_none():
    assert value_to_dbm(0) == -127.0
    assert value_to_dbm(190) == pytest.approx(-27.0)
    assert value_to_dbm(254) == pytest.approx(254 / 1.9 - 127)
    assert value_to_dbm(UNKNOWN) is None
    for garbage in (-1, 256, 1000, True, False, 12.0, math.nan, math.inf, None, "120", b"\x78"):
        assert value_to_dbm(garbage) is None, garbage


def test_the_decoder_inverts_the_simulators_encoder_within_half_a_step():
    for dbm in range(-126, 7):
        assert value_to_dbm(rssi_to_radio_status(dbm)) == pytest.approx(dbm, abs=0.5 / 1.9 + 1e-9)


def test_the_owners_signal_is_the_local_rssi_not_the_remote_one():
    radio = Radio()
    m = parsed(radio.status(rssi=120, remrssi=200))
    assert rssi_dbm(m) == pytest.approx(120 / 1.9 - 127)
    # ArduPilot's older RADIO (166) carries the same fields
    legacy = parsed(bytes(radio.mav.radio_encode(95, 10, 100, 0, 0, 0, 0).pack(radio.mav)))
    assert legacy.get_type() == "RADIO" and rssi_dbm(legacy) == pytest.approx(95 / 1.9 - 127)
    # the simulator's report of a channel decodes to that channel, to SiK's resolution
    sim = parsed(RadioReport().frame(LinkState(-71.3, -95.0, 1.0)))
    assert rssi_dbm(sim) == pytest.approx(-71.3, abs=0.3)


def test_reports_that_are_not_reports_are_none():
    radio = Radio()
    assert rssi_dbm(parsed(radio.status(rssi=UNKNOWN))) is None
    assert rssi_dbm(parsed(bytes(radio.mav.heartbeat_encode(6, 8, 0, 0, 4).pack(radio.mav)))) is None

    class Malformed:
        def __init__(self, kind, rssi) -> None:
            self.kind, self.rssi = kind, rssi

        def get_type(self):
            if self.kind is None:
                raise ValueError("no type")
            return self.kind

    for m in (Malformed("RADIO_STATUS", 70.5), Malformed("RADIO_STATUS", math.nan), Malformed("RADIO_STATUS", None),
              Malformed("RADIO_STATUS", 300), Malformed(None, 70), object(), None, b"\xfd\x09"):
        assert rssi_dbm(m) is None


# ----- on the companion -----------------------------------------------------------------------------------------
def drive_with_radio(rig: Rig, seconds: float, rssi_of_x, speed: float = 2.0, every: float = 1.0) -> None:
    """The pilot drives the rover along x at ``speed``; the radio reports ``rssi_of_x(x)`` every ``every`` s
    from the first step on (``every`` inf: not at all)."""
    radio = Radio()
    next_report = rig.t if math.isfinite(every) else math.inf
    for _ in range(int(round(seconds * 50))):
        rig.ap.x += speed * 0.02
        rig.ap.y = 1.5 * math.sin(rig.ap.x / 1.5)  # (a wiggle: the trail keeps points along a curve)
        rig.step()
        if rig.t >= next_report - 1e-9:
            next_report += every
            rig.companion.from_ground(radio.status(rssi_of_x(rig.ap.x)), rig.t, "radio")


def test_a_radio_status_stream_puts_rssi_on_the_companions_link_map_and_crumbs():
    rig = booted()
    v = rig.companion.vehicle
    drive_with_radio(rig, 20.0, lambda x: 150)
    cells = list(v.linkmap.cells())
    assert len(cells) >= 10  # 40 m of driving over LNK_MAP_CELL-sized cells
    with_rssi = [c for c in cells if math.isfinite(c.rssi_dbm)]
    assert len(with_rssi) >= 0.8 * len(cells)
    assert all(c.rssi_dbm == pytest.approx(150 / 1.9 - 127) for c in with_rssi)
    assert rig.companion.counters["radio_reports"] >= 19
    assert rig.companion.counters.get("radio_ignored", 0) == 0
    # the crumbs laid while the radio reported carry it in their link tag (§6 "plus RSSI when known")
    # (the first, laid at boot before any report, has none)
    rssi = v.trail._f[: v.trail.count, Trail.FIELDS.index("rssi")]
    assert v.trail.count >= 3 and math.isnan(rssi[0])
    assert rssi[1:] == pytest.approx([150 / 1.9 - 127] * (v.trail.count - 1))
    # the radio's report never stands in for the owner: nobody owns the vehicle, so nothing was heard
    assert v.book.owner is None and not v.link_good(rig.t)


def test_the_rssi_of_a_crumb_goes_stale_when_the_radio_stops_reporting():
    rig = booted()
    v = rig.companion.vehicle
    first = rig.t + 0.02
    drive_with_radio(rig, 4.0, lambda x: 100)
    assert v.rssi_at(rig.t) == pytest.approx(100 / 1.9 - 127)
    last = v.rssi_report[0]
    drive_with_radio(rig, STALE_S + 8.0, lambda x: 100, every=math.inf)  # the radio falls silent
    assert math.isnan(v.rssi_at(rig.t)) and math.isfinite(v.rssi_at(last + STALE_S))
    t = v.trail._f[: v.trail.count, Trail.FIELDS.index("t")]
    rssi = v.trail._f[: v.trail.count, Trail.FIELDS.index("rssi")]
    fresh, stale = (t >= first) & (t <= last + STALE_S), t > last + STALE_S
    assert fresh.any() and stale.any()
    assert all(math.isfinite(r) for r in rssi[fresh]) and all(math.isnan(r) for r in rssi[stale])


def test_unknown_and_malformed_reports_are_counted_and_ignored_never_a_crash():
    rig = booted()
    v = rig.companion.vehicle
    radio = Radio()
    c = rig.companion
    c.from_ground(radio.status(UNKNOWN, UNKNOWN, UNKNOWN), rig.t, "radio")  # all 255: a radio that measured nothing
    assert c.counters["radio_ignored"] == 1 and v.rssi_report is None
    good = radio.status(120)
    bad_before = c.counters["bad_frames"]
    c.from_ground(good[:9], rig.t, "radio")  # a frame cut short by the serial link...
    c.from_ground(good, rig.t, "radio")  # ...swallows the next one: bad data, counted
    c.from_ground(b"\xfd\x09\x00\x00\x33\x44\x6d" + bytes(range(40)), rig.t, "radio")  # a garbled header
    assert c.counters["bad_frames"] > bad_before
    assert v.rssi_report is None
    drive_with_radio(rig, 3.0, lambda x: 120)
    assert c.counters["radio_reports"] >= 2 and v.rssi_report is not None
    assert v.rssi_report[1] == pytest.approx(120 / 1.9 - 127)
    assert c.counters["radio_ignored"] == 1
    assert c.healthy and rig.companion.vehicle is v


def test_before_the_vehicle_boots_reports_are_read_and_dropped():
    ap = FakeAutopilot()
    ap.ekf_ok = False  # the autopilot is known, its position estimate not yet good: no vehicle
    rig = Rig(autopilot=ap)
    rig.run(1)
    rig.companion.from_ground(Radio().status(120), rig.t, "radio")
    assert rig.companion.vehicle is None and rig.companion.counters["radio_reports"] == 1
    ap.ekf_ok = True
    assert rig.run(2, lambda: rig.companion.vehicle is not None)
    assert rig.companion.vehicle.rssi_report is None and math.isnan(rig.companion.vehicle.rssi_at(rig.t))


def test_with_a_key_the_radios_unsigned_report_still_counts():
    """A SiK radio cannot sign: its RSSI is used unsigned (as ArduPilot accepts RADIO_STATUS unsigned); it only
    ever goes on the map and the crumbs, never into a lease or the link watch."""
    rig = booted(key=Key(bytes(range(32))))
    drive_with_radio(rig, 2.0, lambda x: 80)
    v = rig.companion.vehicle
    assert v.rssi_report is not None and v.rssi_report[1] == pytest.approx(80 / 1.9 - 127)
    assert v.book.owner is None
