"""MAVProxy (the pip package, headless, reading commands on stdin) flies the simulated vehicle over loopback."""

from __future__ import annotations

import math
import time

import pytest

from link.linkmap_format import decode
from tests.interop import MAVProxy, ServedVehicle, wait_until
from vehicle.app import State
from vehicle.params import SPECS

pytestmark = pytest.mark.interop

PLAN = ("QGC WPL 110\n"
        "0\t1\t2\t44002\t30\t0\t-1\t-1\t0\t0\t0\t1\n"
        "1\t0\t2\t44003\t0\t0\t0\t0\t0\t0\t0\t1\n"
        "2\t0\t2\t19\t20\t0\t0\t0\t0\t0\t0\t1\n")


@pytest.fixture()
def mavproxy(tmp_path):
    served = ServedVehicle("tunnel")
    mp = MAVProxy(served.gcs_port, tmp_path, "wp,param,mode,cmdlong,link,log,fence,arm")
    try:
        mp.wait_for_parameters(len(SPECS))
        yield served, mp.say, mp.log
    finally:
        mp.close()
        served.close()


def test_param_set_show_and_refusal(mavproxy):
    served, say, log = mavproxy
    say("param set LNK_TIMEOUT 5")
    wait_until(lambda: served.vehicle.params["LNK_TIMEOUT"] == 5.0, 20, "LNK_TIMEOUT = 5 on the vehicle")
    say("param show LNK_TIMEOUT")
    wait_until(lambda: "LNK_TIMEOUT      5.0" in log.read_text(), 20, "param show to print 5.0")
    say("param set LNK_TIMEOUT 999")
    wait_until(lambda: "outside 0.5..120" in log.read_text(), 20, "the refusal STATUSTEXT in MAVProxy")
    time.sleep(0.5)
    assert served.vehicle.params["LNK_TIMEOUT"] == 5.0
    assert "fence breach" not in log.read_text()  # no fence, none breached


def test_wp_load_schedules_the_plan_and_mode_rtl_returns(mavproxy, tmp_path):
    served, say, log = mavproxy
    plan = tmp_path / "plan.txt"
    plan.write_text(PLAN)
    say("arm throttle")
    wait_until(lambda: served.vehicle.armed, 20, "arm throttle to arm the vehicle")
    say(f"wp load {plan}")
    wait_until(lambda: "TYPE_MISSION: ACCEPTED" in log.read_text(), 20, "MISSION_ACK accepted")
    assert len(served.vehicle.book.plan) == 2
    assert [it.command for it in served.vehicle.plan_items] == [44002, 44003, 19]
    say("mode RTL")
    wait_until(lambda: "DO_SET_MODE: ACCEPTED" in log.read_text(), 20, "DO_SET_MODE accepted")
    wait_until(lambda: served.vehicle.state() in (State.RETURNING, State.HOLDING), 20, "the return plan to run")
    assert any(e.reason.name == "OPERATOR_EXPIRE" for e in served.vehicle.event_log)


def test_mavproxy_fetches_the_link_map_over_ftp(tmp_path):
    """MAVProxy's own FTP client reads linkmap.csv; with FTP loaded it asks for @PARAM/param.pck first, is told
    FileNotFound, and still gets every parameter by the parameter protocol."""
    served = ServedVehicle("tunnel")
    mp = MAVProxy(served.gcs_port, tmp_path, "ftp,param,link")
    try:
        mp.wait_for_parameters(len(SPECS))
        out = tmp_path / "fetched.csv"
        mp.say(f"ftp get linkmap.csv {out}")
        wait_until(lambda: out.is_file() and out.stat().st_size > 0, 20, "MAVProxy to save linkmap.csv")
        cells = decode(out.read_bytes())
        assert cells and all(math.isfinite(c.north) and math.isfinite(c.east) for c in cells)  # a whole file
    finally:
        mp.close()
        served.close()
