"""MAVLink FTP alone: the files offered are read whole, by ReadFile or by burst; nothing else is served."""

from __future__ import annotations

import struct

from gcs.file_transfer import FileClient
from link import ftp
from tests.service_kit import OWNER, Kit
from vehicle.services.base import mav
from vehicle.services.ftp import BURST_PACKETS, MAX_SESSIONS, FtpServer

CONTENT = bytes(range(256)) * 3  # 768 bytes: four packets, the last one short


def request(seq: int, opcode: int, data: bytes = b"", offset: int = 0, session: int = 0):
    return mav.MAVLink_file_transfer_protocol_message(0, 1, 1, ftp.encode(seq, session, opcode, data, offset))


def server(kit: Kit, **files) -> FtpServer:
    return FtpServer(kit.out, {name: (lambda v=v: v) for name, v in files.items()} or None)


def answers(replies: list) -> list[ftp.Packet]:
    assert all(r.get_type() == "FILE_TRANSFER_PROTOCOL" for r in replies)
    assert all((r.target_system, r.target_component) == (OWNER, 190) for r in replies)
    return [ftp.decode(r.payload) for r in replies]


def opened(kit: Kit, srv: FtpServer, path: str = "linkmap.csv", seq: int = 1) -> ftp.Packet:
    (a,) = answers(kit.send(srv, request(seq, ftp.OP_OPEN_FILE_RO, path.encode() + b"\0")))
    return a


def test_open_says_the_size_and_reads_return_the_file_in_order():
    kit = Kit()
    srv = server(kit, **{"linkmap.csv": CONTENT})
    a = opened(kit, srv, "/linkmap.csv", seq=10)
    assert (a.opcode, a.req_opcode, a.seq) == (ftp.OP_ACK, ftp.OP_OPEN_FILE_RO, 11)
    assert struct.unpack("<I", a.data)[0] == len(CONTENT)
    got, seq = b"", 12
    while True:
        (r,) = answers(kit.send(srv, request(seq, ftp.OP_READ_FILE, bytes(ftp.DATA), len(got), a.session)))
        if r.opcode == ftp.OP_NAK:
            assert r.error == ftp.ERR_EOF
            break
        assert r.offset == len(got)
        got += r.data
        seq += 2
    assert got == CONTENT


def test_a_burst_sends_the_file_then_eof_each_answer_one_sequence_number_further():
    kit = Kit()
    srv = server(kit, **{"linkmap.csv": CONTENT})
    a = opened(kit, srv)
    burst = answers(kit.send(srv, request(5, ftp.OP_BURST_READ_FILE, bytes(ftp.DATA), 0, a.session)))
    assert [p.seq for p in burst] == list(range(6, 6 + len(burst)))
    assert b"".join(p.data for p in burst if p.opcode == ftp.OP_ACK) == CONTENT
    assert (burst[-1].opcode, burst[-1].error, burst[-1].offset, burst[-1].burst_complete) == (
        ftp.OP_NAK, ftp.ERR_EOF, len(CONTENT), True)


def test_a_long_burst_stops_marked_complete_and_goes_on_where_asked():
    kit = Kit()
    big = bytes(ftp.DATA * (BURST_PACKETS + 3))
    srv = server(kit, big=big)
    a = opened(kit, srv, "big")
    first = answers(kit.send(srv, request(3, ftp.OP_BURST_READ_FILE, bytes(ftp.DATA), 0, a.session)))
    assert len(first) == BURST_PACKETS and first[-1].burst_complete and first[-1].opcode == ftp.OP_ACK
    rest = answers(kit.send(srv, request(99, ftp.OP_BURST_READ_FILE, bytes(ftp.DATA), BURST_PACKETS * ftp.DATA,
                                         a.session)))
    assert sum(len(p.data) for p in first + rest if p.opcode == ftp.OP_ACK) == len(big)


def test_the_session_reads_the_snapshot_taken_at_open():
    kit = Kit()
    content = [b"first version"]
    srv = FtpServer(kit.out, {"linkmap.csv": lambda: content[0]})
    a = opened(kit, srv)
    content[0] = b"second, longer version"
    (r,) = answers(kit.send(srv, request(3, ftp.OP_READ_FILE, bytes(ftp.DATA), 0, a.session)))
    assert r.data == b"first version"


def test_a_repeated_request_gets_the_same_answer_and_is_not_run_twice():
    kit = Kit()
    srv = server(kit, **{"linkmap.csv": CONTENT})
    first = opened(kit, srv, seq=7)
    again = opened(kit, srv, seq=7)
    assert again == first and len(srv.sessions) == 1


def test_unknown_paths_writes_and_unknown_opcodes_are_refused_by_name():
    kit = Kit()
    srv = server(kit, **{"linkmap.csv": CONTENT})
    assert opened(kit, srv, "@PARAM/param.pck").error == ftp.ERR_FILE_NOT_FOUND
    (w,) = answers(kit.send(srv, request(3, ftp.OP_CREATE_FILE, b"x.txt\0")))
    assert (w.opcode, w.error) == (ftp.OP_NAK, ftp.ERR_FILE_PROTECTED)
    (u,) = answers(kit.send(srv, request(5, 77)))
    assert (u.opcode, u.error) == (ftp.OP_NAK, ftp.ERR_UNKNOWN_COMMAND)
    (s,) = answers(kit.send(srv, request(7, ftp.OP_READ_FILE, bytes(10), 0, session=3)))
    assert s.error == ftp.ERR_INVALID_SESSION


def test_sessions_are_bounded_and_freed_by_terminate():
    kit = Kit()
    srv = server(kit, **{"linkmap.csv": CONTENT})
    sessions = [opened(kit, srv, seq=2 * k + 1).session for k in range(MAX_SESSIONS)]
    assert sorted(sessions) == list(range(MAX_SESSIONS))
    assert opened(kit, srv, seq=101).error == ftp.ERR_NO_SESSIONS
    (t,) = answers(kit.send(srv, request(103, ftp.OP_TERMINATE_SESSION, session=sessions[0])))
    assert t.opcode == ftp.OP_ACK
    assert opened(kit, srv, seq=105).opcode == ftp.OP_ACK


def test_the_root_lists_the_files_offered_with_their_sizes():
    kit = Kit()
    srv = server(kit, **{"linkmap.csv": CONTENT})
    (r,) = answers(kit.send(srv, request(1, ftp.OP_LIST_DIRECTORY, b"/\0")))
    assert r.data == f"Flinkmap.csv\t{len(CONTENT)}".encode() + b"\0"
    (e,) = answers(kit.send(srv, request(3, ftp.OP_LIST_DIRECTORY, b"/\0", offset=1)))
    assert e.error == ftp.ERR_EOF


def test_an_answer_is_never_answered():
    kit = Kit()
    srv = server(kit)
    assert kit.send(srv, request(1, ftp.OP_ACK)) == [] and kit.send(srv, request(1, ftp.OP_NAK)) == []


def test_the_ground_client_fetches_the_file_whole_over_a_link_that_drops_every_third_frame():
    kit = Kit()
    srv = server(kit, **{"linkmap.csv": CONTENT})
    station = mav.MAVLink(None, OWNER, 190)
    sent: list[bytes] = []
    station.file = type("Sink", (), {"write": lambda self, b: sent.append(bytes(b))})()
    client = FileClient(station, 1, 1)
    d = client.get("linkmap.csv", 0.0)
    n, t = 0, 0.0
    while not d.done and t < 60.0:
        for frame in sent:
            n += 1
            if n % 3 == 0:
                continue  # the request is lost
            for reply in kit.send(srv, kit.parse(frame)):  # (re-framed as the station's)
                n += 1
                if n % 3 != 0:
                    client.on_file_transfer_protocol(reply, t)
        sent.clear()
        t += 0.5
        client.tick(t)
    assert d.ok and bytes(d.data) == CONTENT


def test_the_ground_client_reports_a_file_the_vehicle_does_not_offer():
    kit = Kit()
    srv = server(kit)
    station = mav.MAVLink(None, OWNER, 190)
    sent: list[bytes] = []
    station.file = type("Sink", (), {"write": lambda self, b: sent.append(bytes(b))})()
    client = FileClient(station, 1, 1)
    d = client.get("linkmap.csv", 0.0)
    for reply in kit.send(srv, kit.parse(sent.pop())):
        client.on_file_transfer_protocol(reply, 0.1)
    assert d.done and not d.ok and "file not found" in d.error


def test_an_open_keeps_the_clients_session_number_when_it_is_free():
    """MAVProxy picks its session number and ignores an answer for any other (ArduPilot's server keeps it)."""
    kit = Kit()
    srv = server(kit, **{"linkmap.csv": CONTENT})
    (a,) = answers(kit.send(srv, request(1, ftp.OP_OPEN_FILE_RO, b"linkmap.csv\0", session=111)))
    assert (a.opcode, a.session) == (ftp.OP_ACK, 111)
    (b,) = answers(kit.send(srv, request(3, ftp.OP_OPEN_FILE_RO, b"linkmap.csv\0", session=111)))
    assert b.opcode == ftp.OP_ACK and b.session != 111  # taken: another one
