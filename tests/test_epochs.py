"""Boot epochs (docs/architecture.md §3.1): a real-time vehicle never revives an epoch a delayed command may still
carry."""

from __future__ import annotations

import random

import pytest
from hypothesis import given
from hypothesis import strategies as st

from link.storage import StoredFileError
from sim.cli import main
from sim.scenario import load
from sim.serve import Server
from vehicle import epochs
from vehicle.app import DT
from vehicle.epochs import HEADER, EpochLog, Span, choose, clear_of
from vehicle.services.base import mav

GCS = 255


def test_a_span_counts_up_and_wraps():
    assert Span(65534, 2).covers(65535) and Span(65534, 2).covers(1) and not Span(65534, 2).covers(3)
    assert epochs.after(65535) == 1
    assert not clear_of(100, (Span(500, 510),), headroom=401) and clear_of(100, (Span(500, 510),), headroom=400)


@given(st.lists(st.tuples(st.integers(1, 65535), st.integers(0, 3000)), max_size=epochs.KEEP),
       st.integers(0, 2**32))
def test_a_boot_epoch_is_clear_of_every_recent_boot(raw, seed):
    spans = tuple(Span(first, (first + n - 1) % epochs.SPACE + 1) for first, n in raw)
    rng = random.Random(seed)
    epoch = choose(spans, rng.randrange)
    assert 1 <= epoch <= 65535 and not any(s.covers(epoch) for s in spans)


def test_a_hostile_random_source_still_gives_an_unused_epoch():
    spans = (Span(10, 20),)
    assert choose(spans, lambda n: 14) == 21  # every draw lands in the span: count on past it


@pytest.mark.parametrize("text, line", [
    ("", 1),
    ("# something else\n", 1),
    (HEADER + "\n12 14\n13", 3),
    (HEADER + "\n12 fourteen\n", 2),
    (HEADER + "\n12 70000\n", 2),
])
def test_a_damaged_epochs_file_is_named_with_its_line(tmp_path, text, line):
    path = tmp_path / "returnlink.epochs"
    path.write_text(text)
    with pytest.raises(StoredFileError) as e:
        EpochLog(path)
    assert e.value.line == line and e.value.path == str(path)


def _acked(server: Server, frame: bytes, t: float):
    endpoint = server.plant.endpoint
    endpoint.receive(frame, t)
    server.vehicle.tick(t)
    for out in endpoint.tick(t):
        m = endpoint.parser.parse_buffer(out)[0]
        if m.get_type() == "COMMAND_ACK":
            return m
    raise AssertionError("no COMMAND_ACK")


def _command(command: int, *params: float) -> bytes:
    enc = mav.MAVLink(None, GCS, 190)
    p7 = tuple(params) + (0.0,) * (7 - len(params))
    return enc.command_long_encode(1, 1, command, 0, *p7).pack(enc)


def test_a_restart_never_executes_a_delayed_claim_from_before_it(tmp_path):
    """`sim serve open` restarted five times with the same seed: each boot issues fresh epochs, and a
    LEASE_CLAIM sent before a restart and delivered after it is refused (WRONG_EPOCH), never executed."""
    kept = tmp_path / "returnlink.epochs"
    seen: list[int] = []
    delayed: bytes | None = None
    for _boot in range(5):
        server = Server(load("open"), port=0, peers=(), perfect_link=True, epochs_file=kept)
        try:
            got = _acked(server, _command(mav.MAV_CMD_REQUEST_OPERATOR_CONTROL, 1, 0, 10), DT)
            assert got.result == mav.MAV_RESULT_ACCEPTED
            if delayed is not None:
                late = _acked(server, delayed, 2 * DT)  # the claim from the previous life arrives now
                assert late.result == mav.MAV_RESULT_DENIED
                assert [e.reason.name for e in server.vehicle.event_log] == ["NONE"]
            epoch = server.vehicle.book.epoch
            assert got.result_param2 == epoch and epoch not in seen
            seen.append(epoch)
            delayed = _command(mav.MAV_CMD_LEASE_CLAIM, epoch, 5)  # sent, then the vehicle dies
            assert epochs.parse(kept.read_text(), kept)[-1] == Span(epoch, epoch)  # kept before the ACK left
        finally:
            server.close()
    assert len(epochs.parse(kept.read_text(), kept)) == 5


def test_sim_serve_refuses_to_start_on_a_damaged_epochs_file(tmp_path, capsys):
    (tmp_path / "returnlink.epochs").write_text(HEADER + "\n12 1")
    code = main(["sim", "serve", "open", "--port", "0", "--state", str(tmp_path), "--duration", "1"])
    assert code == 2 and "returnlink.epochs:2: incomplete last line" in capsys.readouterr().err


def test_the_kept_file_steers_a_new_boot_away_from_the_last_ones(tmp_path):
    """Even a random source that repeats itself across boots does not revive an epoch: the file remembers."""
    kept = tmp_path / "returnlink.epochs"
    same = lambda n: 4000  # noqa: E731 - every boot draws 4001
    first = EpochLog(kept, same)
    assert first.boot == 4001 and first.issued(4001) is None and first.issued(4002) is None
    second = EpochLog(kept, same)
    assert second.earlier == (Span(4001, 4002),) and not Span(4001, 4002).covers(second.boot)
    assert EpochLog(None, same).boot == 4001  # nothing kept, nothing avoided


def test_a_file_an_older_boot_wrote_still_reads():
    """The header cites the architecture document now; a robot's file from before that must not stop its boot."""
    from vehicle.epochs import LEGACY_HEADERS, parse

    assert parse(LEGACY_HEADERS[0] + "\n12 14\n", "old.epochs") == parse(HEADER + "\n12 14\n", "new.epochs")
    assert parse(HEADER + "\n12 14\n", "new.epochs")
