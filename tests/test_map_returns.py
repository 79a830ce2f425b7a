"""Where a return goes and where it ends by the link map (docs/architecture.md §6, "The link map"): stories with time
passed in, on the pure planner, the service's way back and the lease book."""

from __future__ import annotations

import numpy as np
import pytest

from vehicle.lease import ExpireReason, Holder, LeaseBook, LeaseConfig, ServiceBlock
from vehicle.linkmap import LinkMap, MapConfig
from vehicle.returning import Target, Way, plan_route, polyline_length
from vehicle.trail import Crumb, Trail

GCS = 255
DT = 0.02


def outbound(good_until: float, heard, length: float = 20.0) -> tuple[Trail, LinkMap]:
    """A straight drive north from 0 to ``length`` m at 1 m/s, off the cell boundary; crumbs tagged good up to
    ``good_until``; the map fed every tick, the owner sending at 10 Hz and ``heard(x)`` saying what arrives."""
    trail, m = Trail(), LinkMap(MapConfig(cell=2.0))
    seq, next_send = 0, 0.0
    n = int(length / DT)
    for k in range(n + 1):
        t = k * DT
        x = length * k / n
        while next_send <= t + 1e-9:
            if heard(x):
                m.packet(t, seq)
            seq += 1
            next_send += 0.1
        m.at(t, x, 1.0)
        trail.add(Crumb(x, 1.0, t, 0.1, x <= good_until))
    return trail, m


def test_the_target_is_the_nearest_place_the_map_vouches_for_not_the_last_lucky_crumb():
    # the crumbs say good up to 15 m (packets trickled through), the map says the link held only up to 8 m
    trail, m = outbound(15.0, lambda x: x < 8.0 or (x < 15.0 and int(x * 10) % 4 == 0))
    route = plan_route(trail, (20.0, 1.0), Target.LINK, 50.0, link_lost=True, linkmap=m, map_depth=2.0)
    assert route.by_map
    gx = route.target[0]
    assert 4.0 <= gx < 8.0 and m.reliable(gx, 1.0) and not m.reliable(gx + 2.0, 1.0)
    # it drives no more path than the trail back to its target, plus the depth into the good place
    assert route.length <= (20.0 - gx) + 2.0 + 1e-6
    # arriving there without the link, it stays: the place held the link, what is missing is not the place
    assert route.onward is None
    # unless the owner expects the station's range to shrink: LNK_MAP_SEEK metres on back along the trail
    seeking = plan_route(trail, (20.0, 1.0), Target.LINK, 50.0, link_lost=True, linkmap=m, map_depth=2.0,
                         map_seek=3.0)
    assert seeking.onward is not None and seeking.onward.points[-1][0] == pytest.approx(gx - 3.0, abs=0.05)
    # without the map it is the last link-good crumb
    plain = plan_route(trail, (20.0, 1.0), Target.LINK, 50.0, link_lost=True)
    assert not plain.by_map and abs(plain.target[0] - 15.0) < 0.6


def test_a_return_goes_on_only_to_a_separate_stretch_where_the_link_held():
    # good 0-6 m, failed 6-10 m, good 10-14 m, dead beyond: the nearest good place is 10-14; if the link is not
    # back there, the next place that held it is the 0-6 m stretch
    trail, m = outbound(14.0, lambda x: x < 6.0 or 10.0 <= x < 14.0)
    route = plan_route(trail, (20.0, 1.0), Target.LINK, 50.0, link_lost=True, linkmap=m, map_depth=2.0)
    assert route.by_map and 10.0 <= route.target[0] < 14.0
    assert route.onward is not None
    end = route.onward.points[-1]
    assert 2.0 <= end[0] < 6.0 and m.reliable(end[0], 1.0)


def test_a_return_stops_inside_a_short_good_place_not_in_the_dead_stretch_beyond_it():
    """The depth into a place the map vouches for stops at the middle of its reliable run: a return that drove the
    whole depth crossed a 2 m good place into a null (a weak radio at a tunnel's portal) and parked there."""
    # good 0-4 m, failed 4-10 m, good 10-12 m only, dead beyond
    trail, m = outbound(12.0, lambda x: x < 4.0 or 10.0 <= x < 12.0)
    route = plan_route(trail, (20.0, 1.0), Target.LINK, 50.0, link_lost=True, linkmap=m, map_depth=3.0)
    assert route.by_map and 10.0 <= route.target[0] < 12.0
    end = route.points[-1]
    assert m.reliable(end[0], end[1]), f"the route ends at {end[0]:.2f} m, outside the place that held"


def test_an_operator_commanded_return_still_goes_to_the_trails_start():
    trail, m = outbound(20.0, lambda x: True)
    route = plan_route(trail, (20.0, 1.0), Target.LINK, 50.0, link_lost=False, linkmap=m)
    assert not route.by_map and route.end[0] < 0.5


def test_the_next_block_of_a_chain_resumes_the_way_and_never_drives_a_stretch_twice():
    pts = np.array([[20.0, 1.0], [10.0, 1.0], [0.0, 1.0]])
    way = Way(pts, np.full(3, 1.0), goal=12.0)
    # the first block got the robot to 16 m (a little off the line); the next one picks up there, heading on back
    rest = way.resumed((16.0, 1.3), way.length)
    assert rest.points[0].tolist() == [16.0, 1.3]
    assert np.all(np.diff(rest.points[1:, 0]) < 0)  # only further back: nothing between 20 and 16 m again
    assert polyline_length(rest.points) < 16.5
    assert abs(rest.goal - 8.3) < 0.05  # the crumb target is 8 m further on (and 0.3 m across)


def returning_book() -> LeaseBook:
    blocks = (ServiceBlock("rtl"), ServiceBlock("hold"))
    book = LeaseBook(config=LeaseConfig(), plan=blocks).acquire(GCS, 190, 0.0).book
    book = book.tick(3.0).book  # COMMS_LOST: the return runs
    assert book.current.holder is Holder.RETURN_SERVICE
    return book.heard(GCS, 10.0).heard(GCS, 10.3).heard(GCS, 10.6).heard(GCS, 11.0)


def test_a_regain_where_the_map_disagrees_does_not_halt_the_return_until_the_place_holds():
    book = returning_book()
    out = book.tick_changes(11.0, place_holds=False)
    assert out is not None and out.events == ()  # heard again, but not here: the return runs on
    book = out.book
    assert not book.link.lost and book.current.holder is Holder.RETURN_SERVICE
    out = book.regained_here(13.0)  # a few metres on, at the place the map vouches for
    (ev,) = out.events
    assert ev.reason is ExpireReason.LINK_REGAINED and ev.expired == 1
    assert out.book.current.holder is Holder.OPERATOR and out.book.scheduled[0].block.payload == "rtl"


def test_a_regain_where_the_map_agrees_halts_at_once():
    (ev,) = returning_book().tick_changes(11.0, place_holds=True).events
    assert ev.reason is ExpireReason.LINK_REGAINED


def test_regained_here_does_nothing_when_the_link_is_lost_again():
    book = returning_book().tick_changes(11.0, place_holds=False).book
    lost = book.tick(20.0).book  # silent since 11 s: lost again
    assert lost.link.lost
    assert lost.regained_here(20.0).events == ()
