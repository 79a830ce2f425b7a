"""``returnlink companion --log DIR`` in-process (docs/architecture.md §11.1): the frames cut from chunks as the
readers cut them, a log pymavlink's reader takes back frame for frame with each frame's direction, a new file per
start that never overwrites one, a directory that cannot take a log refused by name, and a full disk that stops the
log without an exception."""

from __future__ import annotations

import errno
import io
import os
import random
from pathlib import Path

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as apm

from vehicle.companion.links import Framer, is_frame
from vehicle.companion.tlog import FLUSH_EVERY, FROM_AUTOPILOT, FROM_GROUND, TO_AUTOPILOT, TO_GROUND, Tlog, TlogError

START = 1_795_000_000.25  # a fixed Unix time: 2026-11-18T11:06:40.25Z


def frames_from(sysid: int, compid: int, n: int, signed: bool = False) -> list[bytes]:
    """``n`` frames of a few types and lengths (MAVLink 2, signed if asked), as one system sends them."""
    mav = apm.MAVLink(None, sysid, compid)
    if signed:
        mav.signing.secret_key = bytes(32)
        mav.signing.sign_outgoing = True
    out = []
    for i in range(n):
        msg = [apm.MAVLink_heartbeat_message(10, 3, 0, 0, 4, 3),
               apm.MAVLink_local_position_ned_message(i, 1.0, 2.0, 0.0, 0.1, 0.0, 0.0),
               apm.MAVLink_command_long_message(1, 1, 176, 0, 1, 15, 0, 0, 0, 0, 0),
               apm.MAVLink_statustext_message(6, b"x" * (i % 50))][i % 4]
        out.append(bytes(msg.pack(mav)))
    return out


def chunks(data: bytes, rng: random.Random) -> list[bytes]:
    """``data`` cut at random places, as serial reads cut it."""
    out, i = [], 0
    while i < len(data):
        n = rng.randint(1, 60)
        out.append(data[i:i + n])
        i += n
    return out


class Clock:
    def __init__(self, t: float = START) -> None:
        self.t = t

    def __call__(self) -> float:
        self.t += 0.001
        return self.t


# ----- frames ----------------------------------------------------------------------------------------------------
def test_a_stream_cut_anywhere_comes_out_in_its_frames_noise_apart():
    frames = frames_from(1, 1, 20) + frames_from(255, 190, 8, signed=True)
    noise = b"\x00\x01garbage\x55"
    stream = noise + b"".join(frames[:10]) + noise + b"".join(frames[10:])
    f = Framer()
    pieces = [p for c in chunks(stream, random.Random(1)) for p in f.feed(c)]
    assert b"".join(pieces) == stream  # nothing lost, nothing reordered
    assert [p for p in pieces if is_frame(p)] == frames
    assert b"".join(p for p in pieces if not is_frame(p)) == noise * 2


def test_a_datagram_link_drops_an_incomplete_frame_instead_of_gluing_it_to_the_next_datagram():
    a, b = frames_from(1, 1, 2)
    f = Framer(stream=False)
    assert f.feed(a + b[:5]) == [a]
    assert f.feed(b) == [b]  # (a stream would have taken b[:5] + b's first bytes as one frame)


# ----- the log ---------------------------------------------------------------------------------------------------
def read_back(path: Path) -> list[tuple[str, int, int, int]]:
    """(type, source system, source component, direction) of every message pymavlink's tlog reader (the one
    mavlogdump uses) finds."""
    log = mavutil.mavlink_connection(str(path))
    out = []
    while (m := log.recv_msg()) is not None:
        out.append((m.get_type(), m.get_srcSystem(), m.get_srcComponent(), m._link))
    log.close()
    return out


def test_chunks_both_ways_read_back_frame_for_frame_with_their_direction(tmp_path):
    rng = random.Random(2)
    log = Tlog.create(tmp_path, clock=Clock())
    sent = {FROM_AUTOPILOT: frames_from(1, 1, 12), TO_AUTOPILOT: frames_from(1, 191, 5),
            FROM_GROUND: frames_from(255, 190, 7, signed=True), TO_GROUND: frames_from(1, 191, 9)}
    streams = {d: chunks(b"".join(fs), rng) for d, fs in sent.items()}
    while any(streams.values()):  # the four directions interleaved, in chunks, as the loop writes them
        d = rng.choice([d for d, cs in streams.items() if cs])
        log.write(d, streams[d].pop(0))
    log.close()
    got = read_back(log.path)
    assert "BAD_DATA" not in {g[0] for g in got}
    assert len(got) == sum(len(fs) for fs in sent.values()) == log.frames
    parser = apm.MAVLink(None, 0, 0)
    for d, fs in sent.items():
        want = [(m.get_type(), m.get_srcSystem(), m.get_srcComponent(), d)
                for f in fs for m in parser.parse_buffer(f) or []]
        assert [g for g in got if g[3] == d] == want


def test_each_start_gets_a_new_file_named_by_its_utc_start_time_and_none_is_overwritten(tmp_path):
    logs = [Tlog.create(tmp_path / "logs", clock=lambda: START) for _ in range(3)]  # the directory made
    names = [x.path.name for x in logs]
    assert names == ["2026-11-18T11-06-40Z.tlog", "2026-11-18T11-06-40Z-1.tlog", "2026-11-18T11-06-40Z-2.tlog"]
    for x in logs:
        x.write(FROM_AUTOPILOT, frames_from(1, 1, 1)[0])
        x.close()
    assert sorted(p.name for p in (tmp_path / "logs").iterdir()) == sorted(names)


def test_a_log_that_recorded_nothing_is_not_left_behind(tmp_path):
    log = Tlog.create(tmp_path)
    log.close()
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("case", ["a file", "under a file", "not creatable"])
def test_a_directory_that_cannot_take_a_log_is_refused_by_name(tmp_path, case):
    plain = tmp_path / "plain"
    plain.write_text("")
    # (/proc takes no new directory, not even from root, as CI runs)
    directory = {"a file": plain, "under a file": plain / "logs",
                 "not creatable": Path("/proc/returnlink-test-logs")}[case]
    with pytest.raises(TlogError, match=str(directory)):
        Tlog.create(directory)


def test_frames_reach_the_disk_every_second_not_every_frame(tmp_path):
    log = Tlog.create(tmp_path)
    for f in frames_from(1, 1, 10):
        log.write(FROM_AUTOPILOT, f)
    log.flush_if_due()
    assert log.path.stat().st_size == 0  # buffered
    log.flushed_at -= FLUSH_EVERY
    log.flush_if_due()
    assert log.path.stat().st_size == sum(8 + len(f) for f in frames_from(1, 1, 10))
    log.close()


class FullDisk(io.RawIOBase):
    """A file that takes ``room`` bytes, then fails as a full disk does."""

    def __init__(self, room: int) -> None:
        self.room = room
        self.data = bytearray()
        self.attempts = 0

    def writable(self) -> bool:
        return True

    def write(self, b) -> int:
        self.attempts += 1
        if len(self.data) + len(b) > self.room:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        self.data += b
        return len(b)


def test_a_full_disk_stops_the_log_once_without_raising(tmp_path):
    disk = FullDisk(room=500)
    log = Tlog(disk, tmp_path / "x.tlog", clock=Clock())
    for f in frames_from(1, 1, 40):
        log.write(FROM_AUTOPILOT, f)  # never raises: the loop routing this frame must go on
    assert log.failed is not None and "No space left on device" in log.failed
    attempts = disk.attempts
    log.write(FROM_AUTOPILOT, frames_from(1, 1, 1)[0])
    log.flush_if_due()
    log.close()
    assert disk.attempts == attempts  # stopped: no write after the first failure
    assert 0 < log.frames < 40
