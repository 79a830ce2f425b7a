"""The operator's console: the long-lived shell, one-shot commands that never lie about what happened."""

from __future__ import annotations

import io
import math
import socket
import subprocess
import sys
import threading

import numpy as np
import pytest

from gcs.client import Client, GcsError
from gcs.commands import COMMANDS
from gcs.shell import Session, line_parser
from link import dialect
from link.linkmap_format import decode
from sim.cli import main
from sim.driver import SimDriver
from sim.scenario import load
from tests.interop import ServedVehicle, free_udp_port, wait_until
from vehicle.app import DT, Vehicle
from vehicle.endpoint import Endpoint
from vehicle.lease import ExpireReason
from vehicle.params import load_defaults

mav = dialect.load()


def gcs(*args: str, stdin: str | None = None, timeout: float = 40) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "sim.cli", "gcs", *args], input=stdin, capture_output=True,
                          text=True, timeout=timeout)


@pytest.fixture
def served():
    v = ServedVehicle("tunnel")
    try:
        yield v
    finally:
        v.close()


class SimulatedLink:
    """A vehicle in simulated time as a ``Client``'s whole world: its transport (frames in and out) and its clock.
    Time moves only when someone waits: every ``sleep`` of the client or of the shell's background thread steps
    the vehicle through the ticks that fall in it, so a station that stops pumping stops its own clock too."""

    def __init__(self) -> None:
        sc = load("open")
        self.driver = SimDriver(sc, "rover", np.random.default_rng(1))
        self.vehicle = Vehicle(self.driver, load_defaults(), sc.start, 0.0, seed=1)
        self.endpoint = Endpoint(self.vehicle)
        self.now, self.tick_t = 0.0, 0.0
        self.out: list[bytes] = []
        self.lock = threading.Lock()
        self.until, self.reached = math.inf, threading.Event()

    def clock(self) -> float:
        return self.now

    def sleep(self, seconds: float) -> None:
        with self.lock:
            self.now += seconds
            while self.tick_t + DT <= self.now + 1e-9:
                self.tick_t = round(self.tick_t + DT, 9)
                self.vehicle.tick(self.tick_t)
                self.driver.advance(DT)
                self.out.extend(self.endpoint.tick(self.tick_t))
            if self.now >= self.until:
                self.reached.set()

    # the transport the client sends and receives through
    def send(self, frame: bytes) -> None:
        with self.lock:
            self.endpoint.receive(frame, self.tick_t)

    def receive(self) -> list[tuple[bytes, None]]:
        with self.lock:
            out, self.out = self.out, []
        return [(frame, None) for frame in out]

    def close(self) -> None:
        pass


def test_shell_keeps_the_link_through_a_10_s_idle():
    """acquire -> plan -> arm -> 10 s of nobody typing: a one-shot CLI let the vehicle run a return chain in such a
    gap; the shell's background thread keeps the owner heard while it waits for the next line, so no COMMS_LOST.
    In simulated time: the 10 s pass as fast as the background thread's waits step the vehicle."""
    link = SimulatedLink()
    client = Client("udpin:127.0.0.1:0", clock=link.clock, sleep=link.sleep)
    client.transport.close()
    client.transport = link
    out = io.StringIO()
    parser = line_parser()
    with Session(client, out, sleep=link.sleep) as session:
        for line in ("acquire", "plan upload --spec 'rtl:40 | loiter:10 | launch'", "arm"):
            assert session.run_line(line, parser) == 0, out.getvalue()
        assert link.vehicle.armed
        link.until = link.now + 10.0  # the operator thinks; only the session's own thread talks meanwhile
        assert link.reached.wait(20), "the shell stopped talking to the vehicle while it waited"
        assert session.run_line("status", parser) == 0
    text = out.getvalue()
    assert "in control: epoch" in text and "uploaded 5 items" in text and "state TELEOP" in text
    assert "return plan: 5 items, 3 leases" in text  # STATUSTEXTs are printed as they arrive
    assert ExpireReason.COMMS_LOST not in [e.reason for e in link.vehicle.event_log]
    assert link.vehicle.book.owner == 255 and link.vehicle.armed


@pytest.mark.interop
def test_shell_script_stops_at_the_first_refused_command(served):
    script = "acquire\nparam set LNK_TIMEOUT 999\nrtl\n"
    r = gcs("--url", f"udpin:127.0.0.1:{served.gcs_port}", "shell", stdin=script)
    assert r.returncode == 1
    assert "LNK_TIMEOUT refused" in r.stderr and "line 2" in r.stderr
    assert "> rtl" not in r.stdout  # nothing after the refusal ran
    assert served.vehicle.state() != 3  # not RETURNING


@pytest.mark.interop
def test_shell_script_rejects_an_unknown_command_with_exit_2(served):
    r = gcs("--url", f"udpin:127.0.0.1:{served.gcs_port}", "shell", stdin="status\nfly away\n")
    assert r.returncode == 2 and "invalid choice" in r.stderr


@pytest.mark.interop
def test_shell_drives_until_stopped_with_forward_speed_and_turn_rate(served):
    script = "acquire\narm\nmanual 0.5 0\nwait 2\nstop\nstatus\n"
    r = gcs("--url", f"udpin:127.0.0.1:{served.gcs_port}", "shell", stdin=script)
    assert r.returncode == 0, r.stderr
    assert "driving (`stop` to stop)" in r.stdout and "stopped" in r.stdout
    assert served.vehicle.trail.count >= 2  # it moved: crumbs every TRL_SPACING


def test_one_shot_and_shell_share_one_command_table():
    from sim.cli import build_parser

    parser = build_parser()
    for c in COMMANDS:
        if c.where == "shell":
            continue
        words = c.path.split() + {"drive": ["1", "0", "1"], "manual": ["0.5", "0", "1"], "claim": [],
                                  "param set": ["LNK_TIMEOUT", "5"], "param load": ["f"], "param save": ["f"],
                                  "wait": ["1"], "file get": ["linkmap.csv"]}.get(c.path, [])
        assert parser.parse_args(["gcs", *words]).command_path == c.path


@pytest.mark.interop
def test_drive_refused_while_awaiting_claim_exits_1_and_says_claim(served, capsys):
    url = ["gcs", "--url", f"udpin:127.0.0.1:{served.gcs_port}"]
    assert main([*url, "acquire"]) == 0
    assert main([*url, "rtl"]) == 0  # a commanded return over a good link: it ends, the lease awaits a claim
    wait_until(lambda: served.vehicle.state() == 2, 20, "AWAITING_CLAIM")
    capsys.readouterr()
    assert main([*url, "drive", "0.5", "0", "1"]) == 1
    err = capsys.readouterr().err
    assert "drive refused" in err and "AWAITING_CLAIM" in err and "claim" in err
    assert main([*url, "claim"]) == 0
    assert main([*url, "drive", "0.5", "0", "1"]) == 0


@pytest.mark.interop
def test_a_file_that_cannot_be_written_is_a_message_and_exit_2(served, tmp_path, capsys):
    url = ["gcs", "--url", f"udpin:127.0.0.1:{served.gcs_port}"]
    for command in (["plan", "download"], ["param", "save"]):
        assert main([*url, *command, str(tmp_path / "no" / "such" / "file")]) == 2
        assert "cannot write" in capsys.readouterr().err


@pytest.mark.interop
def test_unknown_parameter_is_named_not_a_time_out(served, capsys):
    url = ["gcs", "--url", f"udpin:127.0.0.1:{served.gcs_port}"]
    assert main([*url, "param", "get", "NO_SUCH_PARAM"]) == 1
    err = capsys.readouterr().err
    assert "unknown parameter 'NO_SUCH_PARAM'" in err and "timed out" not in err
    assert main([*url, "param", "set", "NO_SUCH_PARAM", "1"]) == 1
    assert "unknown parameter 'NO_SUCH_PARAM'" in capsys.readouterr().err


@pytest.mark.interop
def test_a_file_the_vehicle_does_not_offer_is_named_not_a_time_out(served, capsys):
    url = ["gcs", "--url", f"udpin:127.0.0.1:{served.gcs_port}"]
    assert main([*url, "file", "get", "@PARAM/param.pck"]) == 1
    err = capsys.readouterr().err
    assert "file @PARAM/param.pck: file not found" in err and "timed out" not in err


@pytest.mark.interop
def test_file_get_saves_the_vehicles_link_map_as_it_has_it(served, tmp_path, capsys):
    url = ["gcs", "--url", f"udpin:127.0.0.1:{served.gcs_port}"]
    out = tmp_path / "linkmap.csv"
    assert main([*url, "file", "get", "linkmap.csv", str(out)]) == 0
    cells = decode(out.read_bytes())  # a whole linkmap.csv: its header and a row per cell the robot has been in
    assert cells and all(math.isfinite(c.north) and math.isfinite(c.east) for c in cells)
    assert f"saved {out.stat().st_size} bytes of linkmap.csv" in capsys.readouterr().out


@pytest.mark.interop
def test_param_set_to_nan_is_reported_refused_not_done(served, capsys):
    """The command line refuses NaN as a bad argument (exit 2); a library caller that sends it anyway is told the
    vehicle refused it, never that it was set (NaN compares unequal to the echoed old value)."""
    url = ["gcs", "--url", f"udpin:127.0.0.1:{served.gcs_port}"]
    with pytest.raises(SystemExit) as e:
        main([*url, "param", "set", "LNK_TIMEOUT", "nan"])
    assert e.value.code == 2 and "finite" in capsys.readouterr().err
    with Client(f"udpin:127.0.0.1:{served.gcs_port}") as c:
        c.connect(10.0)
        with pytest.raises(GcsError, match="LNK_TIMEOUT refused, still 3"):
            c.param_set("LNK_TIMEOUT", float("nan"))
    assert served.vehicle.params["LNK_TIMEOUT"] == 3.0


@pytest.mark.interop
def test_connect_waits_for_the_heartbeat_not_just_any_message():
    """A LEASE_STATUS alone is not a vehicle: ``status`` must not print "vehicle 0, armed no"."""
    port = free_udp_port()
    enc = mav.MAVLink(None, 1, 1)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    nan = float("nan")
    frame = enc.lease_status_encode(0, 7, 0, 0, 65535, 65535, 0, 0, 0, 0, 0, 0xFFFFFFFF, nan, nan, nan, nan, 0.0, nan,
                                    0.0, 0).pack(enc)
    with Client(f"udpin:127.0.0.1:{port}") as c:
        for _ in range(5):
            sock.sendto(frame, ("127.0.0.1", port))
        with pytest.raises(GcsError, match="HEARTBEAT"):
            c.connect(0.5)
        assert c.gs.vehicle.status is not None  # the LEASE_STATUS did arrive; it was not enough
        hb = enc.heartbeat_encode(mav.MAV_TYPE_GROUND_ROVER, mav.MAV_AUTOPILOT_GENERIC, 1, 0, 0).pack(enc)
        sock.sendto(hb, ("127.0.0.1", port))
        c.connect(1.0)
        assert c.gs.vehicle.sysid == 1
    sock.close()


@pytest.mark.interop
def test_status_reports_the_vehicle(served, capsys):
    assert main(["gcs", "--url", f"udpin:127.0.0.1:{served.gcs_port}", "status"]) == 0
    assert capsys.readouterr().out.startswith("vehicle 1  ")


@pytest.mark.interop
def test_closed_stdout_ends_quietly(served):
    proc = subprocess.Popen([sys.executable, "-m", "sim.cli", "gcs", "--url", f"udpin:127.0.0.1:{served.gcs_port}",
                             "param", "get"], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()  # the reader is gone before anything is written, like `| head -0`
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 0
    assert b"Traceback" not in err and b"BrokenPipe" not in err


@pytest.mark.interop
@pytest.mark.parametrize("url", ["bogus", "udpin:127.0.0.1:notaport", "tcp:127.0.0.1:5760"])
def test_bad_url_exits_2_with_a_message(url, capsys):
    with pytest.raises(SystemExit) as e:  # refused by the argument's own type, before anything opens
        main(["gcs", "--url", url, "status"])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert "--url" in err and ("udpin:HOST:PORT" in err or "port" in err)


@pytest.mark.interop
def test_map_port_out_of_range_exits_2_before_connecting(capsys):
    with pytest.raises(SystemExit) as e:
        main(["gcs", "--url", f"udpin:127.0.0.1:{free_udp_port()}", "map", "--port", "99999"])
    assert e.value.code == 2 and "--port" in capsys.readouterr().err


@pytest.mark.interop
def test_one_shot_drive_needs_seconds(capsys):
    """A one-shot command's link ends when it returns: "drive until stopped" would be a lie there."""
    assert main(["gcs", "--url", f"udpin:127.0.0.1:{free_udp_port()}", "drive", "1", "0"]) == 2
    assert "give SECONDS" in capsys.readouterr().err


@pytest.mark.interop
def test_shell_prompt_completes_lists_and_survives_a_bad_line(capsys):
    """At a terminal a bad line is a message, not the end of the session; names complete from the one table."""
    import io

    from gcs.shell import Session, Shell

    with Client(f"udpin:127.0.0.1:{free_udp_port()}") as c, Session(c, io.StringIO()) as session:
        shell = Shell(session, stdin=io.StringIO("fly away\nplan show --spec 'rtl:30 | launch'\nquit\n"))
        shell.use_rawinput = False
        assert shell.completenames("pa") == ["param"]
        assert shell.completedefault("u", "plan u", 5, 6) == ["upload"]
        shell.cmdloop()
        out = session.out.getvalue()
        assert "RETURN_TO_LINK" in out and "RETURN_TO_LAUNCH" in out  # the line after the bad one ran
        shell.do_help("")
        assert "plan upload" in session.out.getvalue() and "quit" in session.out.getvalue()
    assert "invalid choice: 'fly'" in capsys.readouterr().err
