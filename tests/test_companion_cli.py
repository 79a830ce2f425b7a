"""``returnlink companion`` at start: every way it can be started wrong ends in exit 2 and a message naming the
connection or file, never a traceback; and the parameter table ``--check`` prints (docs/architecture.md §11).
Several ground links and the telemetry log (§11.1): both links carry the rover and hear the owner, the log holds
both ways, and a failing link or a full disk is reported while routing goes on."""

from __future__ import annotations

import errno
import os
import socket
import threading
import time

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as apm

from link import dialect
from sim.cli import main
from tests.companion_live import CompanionProcess, LiveStation, pump
from tests.companion_rig import GUIDED, FakeAutopilot
from tests.interop import free_udp_port
from vehicle.companion.app import Companion
from vehicle.companion.cli import CompanionLoop
from vehicle.companion.links import ConnError, parse_conn
from vehicle.companion.setup import check, differing, report
from vehicle.companion.tlog import FROM_AUTOPILOT, FROM_GROUND, TO_AUTOPILOT, TO_GROUND, Tlog
from vehicle.params import Params

pytestmark = pytest.mark.interop


def free_tcp_port() -> int:
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


class FakeAutopilotServer:
    """A TCP server speaking as ``FakeAutopilot`` to whoever connects (as SITL's SERIAL0 does), in a thread."""

    def __init__(self, ap: FakeAutopilot) -> None:
        self.ap = ap
        self.server = socket.socket()
        self.server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.server.bind(("127.0.0.1", 0))
        self.server.listen(1)
        self.port = self.server.getsockname()[1]
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        self.server.settimeout(0.2)
        t0 = time.monotonic()  # one clock for every connection: the stand-in's schedule (heartbeat, reports) runs on
        while not self.stop.is_set():
            try:
                conn, _ = self.server.accept()
            except OSError:
                continue
            conn.settimeout(0.02)
            with conn:
                while not self.stop.is_set():
                    t = time.monotonic() - t0
                    try:
                        self.ap.receive(conn.recv(4096), t)
                    except TimeoutError:
                        pass
                    except OSError:
                        break
                    try:
                        for frame in self.ap.step(t, 0.02):
                            conn.sendall(frame)
                    except OSError:
                        break

    def close(self) -> None:
        self.stop.set()
        self.thread.join(5)
        self.server.close()


@pytest.mark.parametrize("text", ["tcp:127.0.0.1", "tcp::5760", "udpout:host:0", "udpin:host:99999", "bogus:1:2",
                                  "serial:/dev/ttyS0:12345", "5760", ""])
def test_bad_connection_strings_are_refused_by_name(text):
    with pytest.raises(ConnError) as e:
        parse_conn(text)
    assert repr(text) in str(e.value)


@pytest.mark.parametrize("text, kind", [("serial:/dev/ttyAMA0:921600", "serial"), ("tcp:127.0.0.1:5760", "tcp"),
                                        ("udpin:0.0.0.0:14550", "udpin"), ("udpout:10.0.0.2:14550", "udpout"),
                                        ("udp::14550", "udpin"), ("serial:/dev/ttyUSB0", "serial")])
def test_good_connection_strings(text, kind):
    assert parse_conn(text).kind == kind


def test_a_bad_conn_exits_2_naming_it(capsys):
    assert main(["companion", "--autopilot", "tcp:localhost", "--gcs", "udpout:127.0.0.1:14550"]) == 2
    assert "'tcp:localhost'" in capsys.readouterr().err


def test_without_a_ground_side_it_exits_2(capsys):
    assert main(["companion", "--autopilot", "tcp:127.0.0.1:5760"]) == 2
    assert "--gcs" in capsys.readouterr().err


def test_an_unreachable_autopilot_exits_2_naming_the_connection(capsys):
    port = free_tcp_port()
    code = main(["companion", "--autopilot", f"tcp:127.0.0.1:{port}", "--gcs", "udpout:127.0.0.1:14550",
                 "--wait", "1"])
    err = capsys.readouterr().err
    assert code == 2 and f"tcp:127.0.0.1:{port}" in err and "Traceback" not in err


def test_a_silent_autopilot_exits_2(capsys):
    port = free_udp_port()
    code = main(["companion", "--autopilot", f"udpin:127.0.0.1:{port}", "--gcs", "udpout:127.0.0.1:14550",
                 "--wait", "1"])
    err = capsys.readouterr().err
    assert code == 2 and "no autopilot heartbeat" in err and f"udpin:127.0.0.1:{port}" in err


def test_an_autopilot_that_is_not_a_rover_exits_2(capsys):
    server = FakeAutopilotServer(FakeAutopilot(mav_type=apm.MAV_TYPE_QUADROTOR))
    try:
        code = main(["companion", "--autopilot", f"tcp:127.0.0.1:{server.port}", "--gcs",
                     "udpout:127.0.0.1:14550", "--wait", "5"])
    finally:
        server.close()
    err = capsys.readouterr().err
    assert code == 2 and "not ArduPilot Rover" in err


def test_a_damaged_key_file_exits_2(tmp_path, capsys):
    key = tmp_path / "key"
    key.write_text("not a key\n")
    assert main(["companion", "--autopilot", "tcp:127.0.0.1:5760", "--gcs", "udpout:127.0.0.1:14550",
                 "--key", str(key)]) == 2
    assert str(key) in capsys.readouterr().err


def test_check_lists_what_differs_and_configure_sets_it_saying_so(capsys):
    ap = FakeAutopilot()
    ap.params.update(FS_GCS_ENABLE=0.0, FS_ACTION=2.0, FS_GCS_TIMEOUT=5.0, MAV_OPTIONS=1.0)
    server = FakeAutopilotServer(ap)
    try:
        code = main(["companion", "--autopilot", f"tcp:127.0.0.1:{server.port}", "--check", "--wait", "5"])
        out = capsys.readouterr().out
        assert code == 1
        assert [ln.split()[0] for ln in out.splitlines() if "DIFFERS" in ln] == ["FS_GCS_ENABLE", "MAV_OPTIONS"]
        assert "RNGFNDn_TYPE" in out and "the return keeps no standoff" in out  # none set up: said, not failed
        assert ap.params["FS_GCS_ENABLE"] == 0.0  # --check never changes anything
        code = main(["companion", "--autopilot", f"tcp:127.0.0.1:{server.port}", "--configure", "--wait", "5"])
        out = capsys.readouterr().out
        assert code == 0
        assert "set FS_GCS_ENABLE 0 -> 1" in out and "set MAV_OPTIONS 1 -> 0" in out
        assert ap.params["FS_GCS_ENABLE"] == 1.0 and ap.params["MAV_OPTIONS"] == 0.0
    finally:
        server.close()


def test_the_table_names_what_differs():
    rows = check({"FS_GCS_ENABLE": 0.0, "FS_ACTION": 4.0, "FS_GCS_TIMEOUT": 10.0, "MAV_OPTIONS": 0.0})
    assert [r.need.name for r in differing(rows)] == ["FS_GCS_ENABLE", "FS_GCS_TIMEOUT"]
    text = report(rows)
    assert "SYSID_ENFORCE" in text and "absent" in text
    assert [r.need.fix(r.value) for r in differing(rows)] == [1.0, 5.0]


def test_a_serial_link_moves_bytes_both_ways_and_a_missing_port_is_named():
    import os
    import pty

    from vehicle.companion.links import open_link

    master, slave = pty.openpty()
    try:
        link = open_link(parse_conn(f"serial:{os.ttyname(slave)}:57600"))
        os.write(master, b"\xfd\x00")
        deadline = time.monotonic() + 2
        got = []
        while not got and time.monotonic() < deadline:
            got = link.read()
            time.sleep(0.01)
        assert got == [(b"\xfd\x00", None)]
        link.write(b"ok")
        assert os.read(master, 2) == b"ok"
        link.close()
    finally:
        os.close(master)
        os.close(slave)
    with pytest.raises(ConnError, match="serial:/dev/no-such-port:57600"):
        open_link(parse_conn("serial:/dev/no-such-port:57600"))


# ----- several ground links and the log (docs/architecture.md §11.1) ---------------------------------------------
def listening_socket() -> socket.socket:
    """A TCP port that accepts connections but says nothing: whether the companion connected to it can be asked."""
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    s.listen(1)
    s.setblocking(False)
    return s


def connected(server: socket.socket) -> bool:
    try:
        conn, _ = server.accept()
    except BlockingIOError:
        return False
    conn.close()
    return True


@pytest.mark.parametrize("case", ["a file", "under a file"])
def test_a_log_dir_that_cannot_take_a_log_exits_2_naming_it_before_connecting(tmp_path, capsys, case):
    plain = tmp_path / "plain"
    plain.write_text("")
    directory = plain if case == "a file" else plain / "logs"
    server = listening_socket()
    try:
        code = main(["companion", "--autopilot", f"tcp:127.0.0.1:{server.getsockname()[1]}", "--gcs",
                     "udpout:127.0.0.1:14550", "--log", str(directory), "--wait", "1"])
        err = capsys.readouterr().err
        assert code == 2 and f"--log {directory}" in err and "Traceback" not in err
        assert not connected(server)  # refused before anything connected
    finally:
        server.close()


@pytest.mark.parametrize("bad", ["udpout:host", "serial:/dev/no-such-radio:57600"])
def test_any_bad_ground_link_exits_2_naming_it_before_connecting(capsys, bad):
    server = listening_socket()
    try:
        code = main(["companion", "--autopilot", f"tcp:127.0.0.1:{server.getsockname()[1]}", "--gcs",
                     "udpout:127.0.0.1:14550", "--gcs", bad, "--wait", "1"])
        err = capsys.readouterr().err
        assert code == 2 and bad in err and "Traceback" not in err
        assert not connected(server)
    finally:
        server.close()


class Watched(LiveStation):
    """A live ground station that keeps (type, source system, source component) of everything it hears."""

    def __init__(self, sysid: int) -> None:
        super().__init__(sysid)
        self.heard: list[tuple[str, int, int]] = []
        parser = apm.MAVLink(None, 0, 0)
        parser.robust_parsing = True
        feed = self.gs.feed

        def keep(data: bytes, t: float) -> None:
            self.heard += [(m.get_type(), m.get_srcSystem(), m.get_srcComponent())
                           for m in parser.parse_buffer(data) or []]
            feed(data, t)

        self.gs.feed = keep


def test_two_ground_links_both_carry_the_rover_the_owner_is_heard_on_either_and_the_log_has_both_ways(tmp_path):
    ap = FakeAutopilot()
    server = FakeAutopilotServer(ap)
    viewer, owner = Watched(254), Watched(255)  # the radio's side and the network's, each on its own link
    comp = None
    try:
        comp = CompanionProcess(["--autopilot", f"tcp:127.0.0.1:{server.port}", "--gcs",
                                 f"udpout:127.0.0.1:{viewer.port}", "--gcs", f"udpout:127.0.0.1:{owner.port}",
                                 "--log", str(tmp_path / "logs"), "--params", str(tmp_path / "c.parm")], tmp_path)
        for station in (viewer, owner):
            pump([viewer, owner], 30, lambda s=station: ("HEARTBEAT", 1, 1) in s.heard
                 and s.gs.vehicle.status is not None, "the autopilot and the companion on both links")
        for _ in range(5):  # the owner, on the second link, takes the rover by a mode change to the autopilot
            owner.send_autopilot(lambda m: m.command_long_encode(1, 1, 176, 0, 1, GUIDED, 0, 0, 0, 0, 0))
            if pump([viewer, owner], 1, lambda: ap.mode == GUIDED):
                break
        assert ap.mode == GUIDED, comp.text()
        pump([viewer, owner], 5, lambda: any(c == 176 for _, c, _ in owner.gs.acks), "the autopilot's answer")
        assert ("LOCAL_POSITION_NED", 1, 1) in viewer.heard and ("LOCAL_POSITION_NED", 1, 1) in owner.heard
        pump([viewer, owner], 10, lambda: "ground side on" in comp.text(), "the banner")
        assert f"udpout:127.0.0.1:{viewer.port} and udpout:127.0.0.1:{owner.port}" in comp.text()
        assert comp.stop() == 0, comp.text()
    finally:
        if comp is not None:
            comp.stop()
        server.close()
        viewer.close()
        owner.close()
    (path,) = (tmp_path / "logs").iterdir()
    log = mavutil.mavlink_connection(str(path))
    ways: dict[int, set] = {0: set(), 1: set(), 2: set(), 3: set()}
    while (m := log.recv_msg()) is not None:
        ways[m._link].add((m.get_type(), m.get_srcSystem(), m.get_srcComponent()))
    log.close()
    assert {("HEARTBEAT", 1, 1), ("LOCAL_POSITION_NED", 1, 1)} <= ways[FROM_AUTOPILOT]
    assert {("HEARTBEAT", 254, 190), ("HEARTBEAT", 255, 190), ("COMMAND_LONG", 255, 190)} <= ways[FROM_GROUND]
    # the owner's mode change passed on; the companion's own: its keepalive as the GCS, its rate requests
    assert {("COMMAND_LONG", 255, 190), ("HEARTBEAT", 255, 191), ("COMMAND_LONG", 1, 191)} <= ways[TO_AUTOPILOT]
    assert {("HEARTBEAT", 1, 1), ("HEARTBEAT", 1, 191), ("COMMAND_ACK", 1, 1)} <= ways[TO_GROUND]


class ApLink:
    """``FakeAutopilot`` as the loop's autopilot link, in-process on the wall clock: each read is one chunk of all
    it sent since the last (as a serial read is)."""

    def __init__(self, ap: FakeAutopilot) -> None:
        self.ap, self.t0, self.last = ap, time.monotonic(), 0.0

    def fileno(self) -> None:
        return None

    def read(self) -> list[tuple[bytes, None]]:
        t = time.monotonic() - self.t0
        out = b"".join(self.ap.step(t, t - self.last))
        self.last = t
        return [(out, None)] if out else []

    def write(self, data: bytes) -> None:
        self.ap.receive(data, time.monotonic() - self.t0)

    def poll(self) -> None:
        pass

    def close(self) -> None:
        pass


class GroundStub:
    """A ground link in memory: what it was sent, with when; ``fail`` makes every write raise as a broken link."""

    def __init__(self, fail: OSError | None = None) -> None:
        self.sent: list[tuple[float, bytes]] = []
        self.fail = fail
        self.inbox: list[tuple[bytes, object]] = []  # what the next read returns

    def fileno(self) -> None:
        return None

    def read(self) -> list:
        out, self.inbox = self.inbox, []
        return out

    def write(self, data: bytes) -> None:
        if self.fail is not None:
            raise self.fail
        self.sent.append((time.monotonic(), data))

    def poll(self) -> None:
        pass

    def close(self) -> None:
        pass

    def messages(self, since: float = 0.0) -> list:
        parser = dialect.load().MAVLink(None, 0, 0)
        parser.robust_parsing = True
        return [m for t, f in self.sent if t >= since for m in parser.parse_buffer(f) or []]


def loop(log=None) -> CompanionLoop:
    return CompanionLoop(ApLink(FakeAutopilot()), lambda a, g: Companion(Params(), a, g), log)


def test_a_ground_link_that_fails_is_reported_now_and_then_and_the_others_carry_on(capsys):
    shell = loop()
    broken, radio = GroundStub(OSError(errno.ENETUNREACH, os.strerror(errno.ENETUNREACH))), GroundStub()
    shell.add_ground(broken, "udpout:192.0.2.1:14550", datagrams=True)
    shell.add_ground(radio, "serial:/dev/ttyUSB0:57600")
    shell.run_for(1.5)
    reports = [ln for ln in capsys.readouterr().err.splitlines() if "udpout:192.0.2.1:14550" in ln]
    assert len(reports) == 1 and "Network is unreachable" in reports[0]
    assert broken.errors > 10
    late = [m for m in radio.messages(since=time.monotonic() - 0.5) if m.get_srcComponent() == 1]
    assert any(m.get_type() == "LOCAL_POSITION_NED" for m in late)  # the autopilot still reaches the radio


def test_a_full_disk_is_reported_once_the_log_stops_and_routing_goes_on(tmp_path, capsys):
    from tests.test_companion_log import FullDisk

    log = Tlog(FullDisk(room=3000), tmp_path / "x.tlog")
    shell = loop(log)
    radio = GroundStub()
    shell.add_ground(radio, "serial:/dev/ttyUSB0:57600")
    shell.run_for(1.5)
    assert log.failed is not None
    reports = [ln for ln in capsys.readouterr().err.splitlines() if "log stopped" in ln]
    assert len(reports) == 1 and "No space left on device" in reports[0]
    texts = [m.text for m in radio.messages() if m.get_type() == "STATUSTEXT"]
    assert any("log stopped" in t for t in texts), texts  # the ground is told too
    late = [m for m in radio.messages(since=time.monotonic() - 0.5) if m.get_srcComponent() == 1]
    assert any(m.get_type() == "LOCAL_POSITION_NED" for m in late)  # and still hears the rover


def test_a_serial_read_ending_mid_frame_does_not_garble_another_links_datagram():
    shell = loop()
    c = shell.companion
    radio, network = GroundStub(), GroundStub()
    shell.add_ground(radio, "serial:/dev/ttyUSB0:57600")
    shell.add_ground(network, "udpin:0.0.0.0:14550", datagrams=True)
    assert shell.run_for(5, lambda: c.vehicle is not None)
    owner, viewer = apm.MAVLink(None, 255, 190), apm.MAVLink(None, 254, 190)
    command = bytes(owner.command_long_encode(1, 1, apm.MAV_CMD_DO_SET_MODE, 0, 1, GUIDED, 0, 0, 0, 0, 0)
                    .pack(owner))
    radio.inbox.append((command[:9], None))  # the radio's read ends mid-frame...
    network.inbox.append((bytes(viewer.heartbeat_encode(6, 8, 0, 0, 4).pack(viewer)), ("10.0.0.9", 14550)))
    shell.step()  # ...while a datagram comes in on the network
    radio.inbox.append((command[9:], None))
    assert shell.run_for(1, lambda: shell.ap.ap.mode == GUIDED)  # the command arrived whole
    assert c.sources[255] == (0, None) and c.sources[254] == (1, ("10.0.0.9", 14550))  # (link, address)


def test_an_unplugged_serial_radio_and_a_udp_send_error_are_counted_not_raised():
    import pty

    from vehicle.companion.links import open_link

    master, slave = pty.openpty()
    radio = open_link(parse_conn(f"serial:{os.ttyname(slave)}:57600"))
    os.close(slave)
    os.close(master)  # the USB adapter pulled out: writes now fail with EIO
    radio.write(b"\xfd\x00")
    assert radio.errors == 1 and not radio.up and radio.last_error
    radio.write(b"\xfd\x00")  # down: dropped quietly until poll opens it again
    radio.close()
    network = open_link(parse_conn("udpout:255.255.255.255:14550"))  # broadcast without SO_BROADCAST: EACCES
    network.write(b"\xfd\x00")
    assert network.errors == 1 and "Permission denied" in network.last_error
    network.close()
