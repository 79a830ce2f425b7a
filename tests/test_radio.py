"""The simulated radio: distance and walls cost signal, delivery falls off around the sensitivity, runs repeat."""

from __future__ import annotations

from link.radio import Radio, RadioParams, rssi_to_radio_status
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
