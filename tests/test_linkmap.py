"""The link map (vehicle/linkmap.py) and its file (link/linkmap_format.py): time passed in, stories and properties."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from link.linkmap_format import COLUMNS, HEADER, LinkMapFormatError, MapCell, decode, encode
from vehicle.linkmap import OBS_S, LinkMap, MapConfig, wilson_lower

DT = 0.02


def drive(m: LinkMap, t0: float, t1: float, x0: float, x1: float, heard, y: float = 0.0, rate: float = 10.0,
          seq0: int = 0) -> tuple[float, int]:
    """The robot moves from x0 to x1 between t0 and t1 (50 Hz ticks); the owner sends at ``rate``; ``heard(t, x)``
    says whether each packet arrives. Returns the time and the next sequence number."""
    n = int(round((t1 - t0) / DT))
    period = 1.0 / rate
    seq, next_send = seq0, t0
    t = t0
    for k in range(1, n + 1):
        t = t0 + k * DT
        x = x0 + (x1 - x0) * k / n
        while next_send <= t + 1e-9:
            if heard(next_send, x):
                m.packet(t, seq)
            seq += 1
            next_send += period
        m.at(t, x, y)
    return t, seq


# ----- stories ---------------------------------------------------------------------------------------------------
def test_a_place_with_every_packet_is_reliable_and_a_silent_one_is_dead():
    m = LinkMap(MapConfig(cell=2.0))
    t, seq = drive(m, 0.0, 10.0, 0.5, 0.5, lambda t, x: True)  # parked in cell (0, 0), every packet heard
    assert m.rate == pytest.approx(10.0, rel=0.02)
    assert m.reliable(0.5, 0.0)
    t, seq = drive(m, t, t + 6.0, 4.5, 4.5, lambda t, x: False, seq0=seq)  # parked in (2, 0): nothing heard
    cells = {(c.north, c.east): c for c in m.cells()}
    dead = cells[(5.0, 1.0)]
    assert dead.delivered == 0 and dead.expected == pytest.approx(60.0, rel=0.05)
    assert dead.delivery == 0.0 and not m.reliable(4.5, 0.0)
    good = cells[(1.0, 1.0)]
    assert good.delivery > 0.97 and good.observations >= 10.0 / OBS_S - 1


def test_a_silence_is_booked_to_the_cells_crossed_not_to_where_the_next_packet_lands():
    m = LinkMap(MapConfig(cell=2.0))
    t, seq = drive(m, 0.0, 5.0, 0.5, 0.5, lambda t, x: True)
    # drive 0.5 -> 10.5 m in 10 s; the link is dead between 2 and 8 m
    t, seq = drive(m, t, t + 10.0, 0.5, 10.5, lambda t, x: not 2.0 <= x < 8.0, seq0=seq)
    cells = {c.north: c for c in m.cells()}
    for north in (3.0, 5.0, 7.0):
        # (a packet is booked to the cell of the last tick: the one heard on crossing into 8 m may land in 7)
        assert cells[north].delivered <= (1 if north == 7.0 else 0) and cells[north].expected > 15
        assert cells[north].delivery < 0.1
    assert cells[9.0].delivery > 0.9  # where the link came back: what was lost before is not counted here


def test_a_lucky_packet_at_the_fringe_does_not_make_a_place_reliable():
    m = LinkMap(MapConfig(cell=2.0, min_obs=4, margin=0.4, min_quality=0.25))
    t, seq = drive(m, 0.0, 3.0, 0.5, 0.5, lambda t, x: True)
    # a fringe cell, one packet in three
    t, seq = drive(m, t, t + 8.0, 2.5, 2.5, lambda t, x: int(t * 10) % 3 == 0, seq0=seq)
    fringe = next(c for c in m.cells() if c.north == 3.0)
    assert 0.2 < fringe.delivery < 0.5
    assert not m.reliable(2.5, 0.0)
    # and a short look at a perfect place is not enough either
    t, seq = drive(m, t, t + 0.3, 6.5, 6.5, lambda t, x: True, seq0=seq)
    assert not m.reliable(6.5, 0.0)


def test_duplicates_are_not_deliveries_and_late_packets_do_not_move_the_sequence():
    m = LinkMap(MapConfig(cell=2.0))
    m.at(0.0, 0.0, 0.0)
    for k in range(20):
        m.packet(k * 0.1, k)
        m.packet(k * 0.1, k)  # each one twice
        m.at(k * 0.1 + 0.05, 0.0, 0.0)
    c = next(iter(m.cells()))
    assert c.delivered == 20
    m.packet(2.0, 5)  # a late one
    assert m._seq == 19  # noqa: SLF001 - the newest number stays


def test_first_reliable_finds_the_nearest_reliable_place_along_a_route():
    m = LinkMap(MapConfig(cell=2.0))
    drive(m, 0.0, 20.0, 0.5, 20.5, lambda t, x: x < 8.0)  # good up to 8 m, dead beyond
    route = np.array([[19.0, 0.0], [10.0, 0.0], [0.0, 0.0]])  # the way back
    k, u = m.first_reliable(route)
    x = route[k][0] + u * (route[k + 1][0] - route[k][0])
    assert 4.0 <= x < 8.0 and m.reliable(x, 0.0)
    assert m.first_reliable(route[:2]) is None  # nothing reliable between 19 and 10 m


def test_new_parameters_a_new_cell_size_starts_a_new_map():
    m = LinkMap(MapConfig(cell=2.0))
    drive(m, 0.0, 5.0, 0.5, 0.5, lambda t, x: True)
    m.with_config(MapConfig(cell=2.0, margin=0.1))
    assert len(m) == 1
    m.with_config(MapConfig(cell=4.0))
    assert len(m) == 0


# ----- properties ------------------------------------------------------------------------------------------------
@given(st.integers(1, 5000), st.floats(0.0, 1.0), st.integers(1, 50))
def test_wilson_bound_is_monotone_and_below_the_ratio(n, p, extra):
    k = round(p * n)
    lo = wilson_lower(k, n)
    assert 0.0 <= lo <= k / n + 1e-12
    if k < n:
        assert wilson_lower(k + 1, n) >= lo  # one more packet delivered never lowers it
    assert wilson_lower(k * extra, n * extra) >= lo - 1e-12  # the same ratio over more packets never lowers it


walks = st.lists(st.tuples(st.floats(-500, 500), st.floats(-500, 500), st.booleans()), min_size=1, max_size=300)


@settings(max_examples=60, deadline=None)
@given(walks, st.integers(16, 64))
def test_memory_never_exceeds_the_bound(points, bound):
    m = LinkMap(MapConfig(cell=1.0, max_cells=bound))
    for k, (x, y, heard) in enumerate(points):
        t = k * DT
        if heard:
            m.packet(t, k)
        m.at(t, x, y)
        assert len(m) <= bound


@settings(max_examples=30, deadline=None)
@given(walks)
def test_the_same_inputs_give_the_same_map(points):
    def build() -> bytes:
        m = LinkMap(MapConfig(cell=1.5, max_cells=16))
        for k, (x, y, heard) in enumerate(points):
            t = k * DT
            if heard:
                m.packet(t, k % 256)
            m.at(t, x, y)
        return encode(m.cells())

    assert build() == build()


def test_eviction_drops_the_farthest_cells_first():
    m = LinkMap(MapConfig(cell=1.0, max_cells=16))
    for k in range(40):  # a straight drive north through 40 cells
        m.packet(k * 1.0, k)
        m.at(k * 1.0, k + 0.5, 0.5)
    norths = sorted(c.north for c in m.cells())
    assert len(norths) <= 16 and norths[-1] == 39.5
    assert norths == list(np.arange(norths[0], 40.0, 1.0))  # the ones kept are the nearest, without holes
    assert m.evictions >= 1


# ----- the file ----------------------------------------------------------------------------------------------------
def test_linkmap_csv_round_trips_and_names_its_columns():
    cells = [MapCell(1.0, -3.0, 7, 33.25, 30, 30 / 33.25, 0.8, -48.5, 12.5),
             MapCell(45.0, 5.0, 3, 12.0, 0, 0.0, 0.0, math.nan, 40.0),
             MapCell(0.0, 0.0, 0, 0.0, 0, math.nan, 0.0, math.nan, 0.0)]
    data = encode(cells)
    assert data.decode().splitlines()[0] == HEADER
    assert {"north", "east", "observations", "delivery", "rssi_dbm"} <= set(COLUMNS)
    back = decode(data)
    assert len(back) == 3
    assert back[0].north == 1.0 and back[0].observations == 7 and back[0].delivery == pytest.approx(0.9023, abs=1e-4)
    assert math.isnan(back[1].rssi_dbm) and math.isnan(back[2].delivery)


@pytest.mark.parametrize("text, line, field", [
    ("", 1, ""),
    ("north,east,observations\n", 1, "delivery"),
    (HEADER + "\n1,2,3,4,5,0.5,0.1,-50,1\n1,x,3,4,5,0.5,0.1,-50,1\n", 3, "east"),
    (HEADER + "\n1,2,3,4,5,1.5,0.1,-50,1\n", 2, "delivery"),
    (HEADER + "\n1,2,-3,4,5,0.5,0.1,-50,1\n", 2, "observations"),
])
def test_a_bad_linkmap_csv_is_named_by_line_and_field(text, line, field):
    with pytest.raises(LinkMapFormatError) as e:
        decode(text)
    assert (e.value.line, e.value.field) == (line, field)



def test_the_map_pages_link_layer_is_made_from_the_csv_bytes():
    from gcs.linkmap_layer import layer

    cells = [MapCell(1.0, 1.0, 7, 30.0, 30, 1.0, 0.9, -45.0, 3.0), MapCell(3.0, 1.0, 5, 20.0, 2, 0.1, 0.01, -95.0, 5.0),
             MapCell(5.0, 1.0, 0, 0.0, 0, math.nan, 0.0, math.nan, 6.0)]
    lay = layer(encode(cells))
    assert lay["error"] is None and lay["cell"] == 2.0
    assert lay["cells"] == [[1.0, 1.0, 1.0, 7], [3.0, 1.0, 0.1, 5], [5.0, 1.0, None, 0]]
    bad = layer(b"north,east\n1,2\n")
    assert bad["cells"] == [] and "line 1" in bad["error"]


def test_a_fast_straight_drive_leaves_the_map_vouching_near_where_the_link_was_lost_not_far_back():
    # issue 28: at 2 m/s a 2 m cell is crossed in a second, two looks, one short of LNK_MAP_OBS; judged alone no
    # cell on the drive was reliable and the return drove back to where the robot had dawdled near home
    m = LinkMap(MapConfig(cell=2.0))
    t, seq = drive(m, 0.0, 10.0, 0.5, 0.5, lambda t, x: True)  # waiting at home: a well known place
    t, seq = drive(m, t, t + 15.0, 0.5, 30.5, lambda t, x: x < 25.0, seq0=seq)  # heard up to 25 m
    fast = [c for c in m.cells() if 4.0 < c.north < 24.0]
    assert fast and all(c.observations < 3 for c in fast)
    route = np.array([[30.0, 0.0], [0.0, 0.0]])  # the way back
    k, u = m.first_reliable(route, skip=30.0 - 25.0)
    x = 30.0 - u * 30.0
    assert 18.0 <= x < 25.0, f"the map vouches first for {x:.1f} m"
    assert not m.reliable(25.5, 0.0) and not m.reliable(27.0, 0.0)  # the fringe and beyond never


def test_a_short_look_is_judged_with_its_neighbours_and_a_dead_one_drags_it_down():
    m = LinkMap(MapConfig(cell=2.0))
    t, seq = drive(m, 0.0, 3.0, 0.5, 6.5, lambda t, x: x < 4.0)  # 2 m/s: good, good, then dead at 4 m
    assert not m.reliable(3.0, 0.0)  # beside the dead cell: the pooled bound is low
