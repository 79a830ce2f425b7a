"""The live map: the station's track (pure), the HTTP side, and the page in a real headless Chromium."""

from __future__ import annotations

import json
import math
import time
import urllib.error
import urllib.request

import pytest

from gcs.client import Client
from gcs.linkmap_layer import VehicleSource
from gcs.mapserver import MapServer
from gcs.plans import parse_spec
from gcs.track import LOST_GAP, MAX_POINTS, MIN_STEP, Track, return_route
from tests.interop import ServedVehicle, wait_until

pytestmark = pytest.mark.interop

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]


# ----- the track (station time passed in) ------------------------------------------------------------------------
def test_track_quality_is_the_share_of_expected_reports_heard():
    tr = Track(rate=4.0)
    for k in range(12):  # 4 Hz for 3 s: every report heard
        tr.add(k * 0.25, k * 0.5, 0.0)
    assert tr.points[-1].quality == 1.0
    for k in range(4):  # then one report a second: a quarter of them
        tr.add(3.0 + k, 6.0 + k, 0.0)
    assert tr.points[-1].quality == pytest.approx(0.25, abs=0.13)


def test_track_marks_where_the_reports_stopped_as_the_loss_point():
    tr = Track()
    for k in range(8):
        tr.add(k * 0.25, k * 1.0, 0.0)
    assert tr.lost == []
    tr.add(1.75 + LOST_GAP + 3.0, 20.0, 5.0)  # the next report, after a silence
    assert [(p.north, p.east) for p in tr.lost] == [(7.0, 0.0)]
    assert tr.points[-1].quality < 0.2  # heard again, but not yet well


def test_track_keeps_moving_points_only_and_stays_bounded():
    tr = Track()
    for k in range(100):
        tr.add(k * 0.25, 0.01 * k, 0.0)  # creeping: 1 cm per report
    assert len(tr.points) <= 1 + 1.0 / MIN_STEP + 1
    for k in range(3 * MAX_POINTS):
        tr.add(100 + k * 0.25, float(k), 0.0)
    assert len(tr.points) <= MAX_POINTS and tr.points[-1].north == 3 * MAX_POINTS - 1


def test_return_route_walks_the_track_back_to_the_target_inside_the_circle():
    tr = Track()
    for k in range(41):
        tr.add(k * 0.25, float(k), 0.0)  # a straight drive north, 0 to 40 m
    route = return_route(tr, (40.0, 0.0), (40.0, 0.0), (5.0, 0.0), math.inf)
    assert route[0] == (40.0, 0.0) and route[-1] == (5.0, 0.0)
    assert [p[0] for p in route] == sorted((p[0] for p in route), reverse=True)
    clipped = return_route(tr, (40.0, 0.0), (40.0, 0.0), (5.0, 0.0), 10.0)
    assert min(p[0] for p in clipped) == 30.0  # stops on the 10 m displacement circle (FIG. 4C)
    assert return_route(tr, (40.0, 0.0), None, None, 10.0) == []


# ----- the server and the page -----------------------------------------------------------------------------------
@pytest.fixture
def mapped():
    served = ServedVehicle("tunnel")
    client = Client(f"udpin:127.0.0.1:{served.gcs_port}")
    server = None
    try:
        client.connect(10)
        # the link layer as `returnlink gcs map` gets it: the vehicle's own linkmap.csv over MAVLink FTP
        server = MapServer(client, 0, linkmap=VehicleSource(client.gs)).start()
        yield served, client, server
    finally:
        if server is not None:
            server.close()
        client.close()
        served.close()


def test_map_is_served_on_loopback_only_and_refuses_unknown_actions(mapped):
    served, client, server = mapped
    assert server.httpd.server_address[0] == "127.0.0.1"
    state = json.loads(urllib.request.urlopen(server.url + "state", timeout=5).read())
    assert state["vehicle"] == 1 and state["lease"]["state"] == "NO_OWNER"
    assert state["plan"] == "default plan (one return to link)"  # from the mission download
    with server.station.session.lock:
        client.acquire()
        client.upload(parse_spec("rtl:40 | loiter:10 | launch"))
    wait_until(lambda: "RETURN_TO_LINK" in json.loads(urllib.request.urlopen(server.url + "state", timeout=5).read())
               ["plan"], 5, "the new plan on the map")
    with pytest.raises(urllib.error.HTTPError) as e:
        urllib.request.urlopen(urllib.request.Request(server.url + "action/selfdestruct", method="POST"), timeout=5)
    assert e.value.code == 404
    assert served.vehicle.state() == 1  # TELEOP: the unknown action changed nothing


def test_map_page_in_headless_chromium_shows_the_trail_grow_and_rtl(mapped, tmp_path):
    from playwright.sync_api import sync_playwright

    served, client, server = mapped
    with sync_playwright() as pw:
        ctx = pw.chromium.launch_persistent_context(str(tmp_path / "profile"), executable_path=CHROMIUM,
                                                    args=CHROMIUM_ARGS, headless=True)
        try:
            page = ctx.new_page()
            page.goto(server.url)
            page.click("#btn-acquire")
            page.wait_for_function("document.getElementById('state').textContent === 'TELEOP'", timeout=10_000)
            assert served.vehicle.book.owner == 255
            with server.station.session.lock:
                client.arm()
                client.gs.drive_velocity(0.8, 0.0)  # the background thread streams it
            count = lambda: int(page.get_attribute("#trail", "data-count"))  # noqa: E731
            first = count()
            wait_until(lambda: count() >= first + 5, 20, "the trail to grow on the page")
            assert page.locator("#trail polyline.trail-good").count() >= 1  # a perfect link: all good
            # the link layer: the vehicle's map of where its owner's packets arrived, every cell good here
            wait_until(lambda: int(page.get_attribute("#linkmap", "data-count")) >= 2, 20, "the link layer")
            assert page.locator("#linkmap rect.linkmap-good").count() >= 1
            assert page.locator("#linkmap rect.linkmap-poor").count() == 0
            with server.station.session.lock:
                client.stop_driving()
            page.click("#btn-rtl")
            page.wait_for_function("['RETURNING', 'AWAITING_CLAIM'].includes("
                                   "document.getElementById('state').textContent)", timeout=10_000)
            assert page.text_content("#answer") == "returning"
            assert "OPERATOR_EXPIRE" in page.text_content("#events")
            page.wait_for_function("document.getElementById('displacement-circle') !== null", timeout=5_000)
            time.sleep(0.5)
            page.screenshot(path=str(tmp_path / "map.png"))
            assert (tmp_path / "map.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        finally:
            ctx.close()
