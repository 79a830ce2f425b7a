"""The simulated radio: distance and walls cost signal, delivery falls off around the sensitivity, runs repeat."""

from __future__ import annotations

import hashlib
import math
import re
import struct
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from link.radio import Radio, RadioParams, rssi_to_radio_status, subsystem_seed
from link.transports import LockstepBus
from sim import scenario


def test_distance_and_walls_reduce_rssi_and_delivery():
    p = RadioParams(shadowing_db=0.0)
    open_air = Radio(p, lambda a, b: 0.0, seed=1)
    near = open_air.link((0, 0), 20.0, (10.0, 0.0))
    far = open_air.link((0, 0), 20.0, (3000.0, 0.0))
    assert near.rssi_dbm > far.rssi_dbm + 20
    assert near.delivery > 0.99 and far.delivery < 0.5
    walled = Radio(p, lambda a, b: 30.0, seed=1).link((0, 0), 20.0, (10.0, 0.0))
    assert abs((near.rssi_dbm - walled.rssi_dbm) - 30.0) < 1e-9


def test_a_place_behind_hundreds_of_db_of_rock_is_dead_not_a_crash():
    # generated mine worlds put several 30-60 dB walls between a station and the end of a drift; the delivery's
    # logistic overflowed math.exp there and took the run down
    radio = Radio(RadioParams(shadowing_db=0.0), lambda a, b: 900.0, seed=1)
    assert radio.link((0, 0), 20.0, (10.0, 0.0)).delivery < 1e-300
    gain = Radio(RadioParams(shadowing_db=0.0), lambda a, b: -900.0, seed=1)
    assert gain.link((0, 0), 20.0, (10.0, 0.0)).delivery == 1.0


def test_tunnel_bend_kills_the_link():
    s = scenario.load("tunnel")
    world = s.world()
    p = RadioParams(shadowing_db=0.0)
    radio = Radio(p, world.attenuation_db, seed=1)
    g = s.stations[0]
    before_bend = radio.link((g.x, g.y), g.power_dbm, (35.0, 0.0))
    after_bend = radio.link((g.x, g.y), g.power_dbm, (50.0, 10.0))
    assert before_bend.delivery > 0.95 and after_bend.delivery < 0.01


def test_packet_fates_are_seeded_and_lossy_where_weak():
    p = RadioParams()
    a = Radio(p, lambda x, y: 0.0, seed=3)
    b = Radio(p, lambda x, y: 0.0, seed=3)
    st = a.link((0, 0), 0.0, (200.0, 0.0))
    st_b = b.link((0, 0), 0.0, (200.0, 0.0))
    fates_a = [a.packet(st) for _ in range(500)]
    fates_b = [b.packet(st_b) for _ in range(500)]
    assert fates_a == fates_b
    assert 0 < a.lost < 500
    assert rssi_to_radio_status(-127) == 0 and rssi_to_radio_status(-60) == 127


def _jittery(reorder: bool) -> RadioParams:
    # jitter far larger than the gap between packets: drawn latencies alone would reorder most neighbours
    return RadioParams(shadowing_db=0.0, latency_ms=20.0, jitter_ms=15.0, reorder=reorder)


def test_a_packet_fate_is_the_keyed_hash_of_its_send_time_and_rank():
    """The fate of a direction's packet is BLAKE2b keyed by that direction, over the send time (µs) and the rank
    among its packets at that time: the recorded runs hold these values, however the hash is computed."""
    radio = Radio(RadioParams(), lambda a, b: 0.0, seed=7)
    keys = {name: subsystem_seed(7, f"radio.{name}").generate_state(4).tobytes()
            for name in ("uplink.gcs", "downlink.gcs")}
    sends = [("uplink.gcs", 0.02, 0), ("downlink.gcs", 0.02, 0), ("uplink.gcs", 0.02, 1), ("uplink.gcs", 0.02, 2),
             ("downlink.gcs", 0.02, 1), ("uplink.gcs", 0.04, 0), ("downlink.gcs", 1.5, 0)]
    for name, t, rank in sends:
        digest = hashlib.blake2b(struct.pack("<qI", round(t * 1e6), rank), digest_size=24, key=keys[name]).digest()
        assert radio._uniforms(name, t) == tuple((w + 0.5) / 2.0**64 for w in struct.unpack("<QQQ", digest))


def test_each_direction_keeps_its_order_while_latency_varies():
    radio = Radio(_jittery(False), lambda a, b: 0.0, seed=5)
    state = radio.link((0, 0), 20.0, (10.0, 0.0))
    up = [radio.arrival(state, 0.002 * k, ("gcs", "vehicle")) for k in range(300)]
    down = [radio.arrival(state, 0.002 * k + 0.001, ("vehicle", "gcs")) for k in range(300)]
    up = [a for a in up if a is not None]
    down = [a for a in down if a is not None]
    for got in (up, down):
        assert len(got) > 250
        assert got == sorted(got)
        assert max(b - a for a, b in zip(got, got[1:], strict=False)) > 0.003  # latency still varies
    # the directions are independent: a slow packet one way does not hold back the other way
    assert min(down) < max(up)


def test_reordering_is_a_radio_option_off_by_default():
    assert RadioParams().reorder is False
    radio = Radio(_jittery(True), lambda a, b: 0.0, seed=5)
    state = radio.link((0, 0), 20.0, (10.0, 0.0))
    got = [a for a in (radio.arrival(state, 0.002 * k, "up") for k in range(300)) if a is not None]
    assert got != sorted(got)


def test_two_chunk_statustext_arrives_head_first_through_the_bus():
    """Over a jittery link the tail chunk used to overtake the head (MAVSDK and the CLI showed it tail first)."""
    bus = LockstepBus()
    radio = Radio(_jittery(False), lambda a, b: 0.0, seed=11)
    state = radio.link((0, 0), 20.0, (10.0, 0.0))
    sent = []
    for k in range(200):
        t = 0.02 * (k // 2)  # two frames in the same tick, as a two-chunk STATUSTEXT leaves
        at = radio.arrival(state, t, ("vehicle", "gcs"))
        if at is not None:
            bus.send("vehicle", "gcs", bytes([k]), at)
            sent.append(k)
    got = []
    for k in range(1, 200):
        got += [d[0] for d, _ in bus.receive("gcs", 0.02 * k)]
    assert got == sent


def test_a_scenario_radio_table_expresses_the_subt_virtual_radio(tmp_path):
    """DARPA SubT virtual radio: RSSI = 20 dBm - (40 dB + 10 * 2.5 * log10 d) + N(0, 10 dB), noise floor -90."""
    text = (Path(scenario.__file__).parent / "scenarios" / "open.toml").read_text()
    text = re.sub(r"\[radio\][^\[]*", "", text)
    text = re.sub(r"power_dbm = [-\d.]+", "power_dbm = 20.0", text)
    text += ("\n[radio]\nexponent = 2.5\nref_loss_db = 40.0\nshadowing_db = 10.0\nnoise_floor_dbm = -90.0\n"
             "reorder = false\n")
    path = tmp_path / "subt.toml"
    path.write_text(text)
    sc = scenario.load(str(path))
    p = sc.radio
    assert (p.exponent, p.ref_loss_db, p.shadowing_db, p.noise_floor_dbm, p.reorder) == (2.5, 40.0, 10.0, -90.0,
                                                                                           False)
    g = sc.stations[0]
    assert g.power_dbm == 20.0
    flat = Radio(replace(p, shadowing_db=0.0), lambda a, b: 0.0, seed=2)
    for d in (1.0, 10.0, 50.0, 200.0):
        st = flat.link((g.x, g.y), g.power_dbm, (g.x + d, g.y))
        assert st.rssi_dbm == pytest.approx(20.0 - (40.0 + 25.0 * math.log10(d)), abs=1e-9)
        assert st.noise_dbm == -90.0
    # with the 10 dB spread: the same mean, a spread of about 10 dB over many places
    radio = Radio(p, lambda a, b: 0.0, seed=2)
    rng = np.random.default_rng(0)
    dev = []
    for x, y in rng.uniform(-500.0, 500.0, size=(4000, 2)):
        d = max(1.0, math.hypot(x - g.x, y - g.y))
        dev.append(radio.link((g.x, g.y), g.power_dbm, (x, y)).rssi_dbm - (20.0 - 40.0 - 25.0 * math.log10(d)))
    assert abs(float(np.mean(dev))) < 1.0
    assert 8.0 < float(np.std(dev)) < 12.0


def test_a_radio_option_that_is_not_a_flag_is_refused(tmp_path):
    text = (Path(scenario.__file__).parent / "scenarios" / "open.toml").read_text()
    text = re.sub(r"\[radio\][^\[]*", "", text) + "\n[radio]\nreorder = 1\n"
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(scenario.ScenarioError, match="radio.reorder"):
        scenario.load(str(path))
