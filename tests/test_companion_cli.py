"""``returnlink companion`` at start: every way it can be started wrong ends in exit 2 and a message naming the
connection or file, never a traceback; and the parameter table ``--check`` prints (docs/architecture.md §11)."""

from __future__ import annotations

import socket
import threading
import time

import pytest
from pymavlink.dialects.v20 import ardupilotmega as apm

from sim.cli import main
from tests.companion_rig import FakeAutopilot
from tests.interop import free_udp_port
from vehicle.companion.links import ConnError, parse_conn
from vehicle.companion.setup import check, differing, report


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
        while not self.stop.is_set():
            try:
                conn, _ = self.server.accept()
            except OSError:
                continue
            conn.settimeout(0.02)
            t0 = time.monotonic()
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
