"""A checksum-aware MAVLink fuzzer for the vehicle: well-framed frames with hostile content.

Random bytes almost never pass a MAVLink CRC (with CRC_EXTRA), so they only exercise the framer. These frames are
built by pymavlink's own encoder, so the CRC and CRC_EXTRA are right and every frame reaches the message handlers,
for every message of the returnlink dialect (common.xml + ours), with random and extreme field values: NaN,
infinities, huge and negative numbers, integer limits, empty and overlong strings, random target ids, random and
real command ids with hostile parameters, mission uploads with random items. A share of the frames is truncated,
garbled or glued to garbage.

Properties (``Fuzzer.run``): the vehicle never raises and no handler faults; a frame from a sysid that does not own
the vehicle never changes its state (lease book, parameters, plan, armed, mode); frames from the owner may change
state but never crash it. Used by ``tests/test_fuzz.py`` (a seeded run in the suite) and ``tests/fuzz_main.py``
(``make fuzz``: a longer run).
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass, field

from link.plan_items import KINDS
from tests.harness import Pair
from vehicle.params import SPECS
from vehicle.services.base import mav
from vehicle.services.native import COMMANDS, HANDLED

OWNER = 255
VEHICLE = 1
INT_RANGES = {"int8_t": (-2**7, 2**7 - 1), "uint8_t": (0, 2**8 - 1), "int16_t": (-2**15, 2**15 - 1),
              "uint16_t": (0, 2**16 - 1), "int32_t": (-2**31, 2**31 - 1), "uint32_t": (0, 2**32 - 1),
              "int64_t": (-2**63, 2**63 - 1), "uint64_t": (0, 2**64 - 1)}
FLOAT_EXTREMES = (math.nan, math.inf, -math.inf, 0.0, -0.0, 1.0, -1.0, 0.5, 3.4e38, -3.4e38, 1e-45, 2.0**31,
                  -2.0**31, 65535.0, 65536.0, 1e7, 255.0, 256.0)
DOUBLE_EXTREMES = (*FLOAT_EXTREMES, 1.7e308, -1.7e308)
PARAM_NAMES = [s.name for s in SPECS]
COMMAND_IDS = sorted(COMMANDS)
ITEM_COMMANDS = sorted(KINDS)
MESSAGES = dict(sorted(mav.mavlink_map.items()))


def snapshot(pair: Pair) -> tuple:
    """The vehicle state a non-owner must never change (telemetry rates and link statistics are not state)."""
    v, ep = pair.vehicle, pair.endpoint
    return (v.book, tuple(v.params.values.values()), v.plan_items, v.armed, v.holding, v.state(),
            ep.custom_mode(), v.setpoint, tuple(ep.missions.lists.values()))


@dataclass
class Report:
    frames: int = 0
    owner_frames: int = 0
    garbled: int = 0
    reached: set[int] = field(default_factory=set)  # message ids the vehicle parsed and dispatched
    state_changes: list[str] = field(default_factory=list)  # non-owner frames that changed state
    crashes: list[str] = field(default_factory=list)


class Generator:
    """Frames for one seed. ``frame(sysid)`` is one random message of the dialect, well framed."""

    def __init__(self, seed: int) -> None:
        self.rng = random.Random(seed)
        self.encoders: dict[int, object] = {}
        self.ids = list(MESSAGES)
        # half of the frames are messages the vehicle acts on, so hostile content reaches the handlers often
        self.handled = [i for i, c in MESSAGES.items() if c.msgname in HANDLED]
        self.handled += [mav.MAVLINK_MSG_ID_COMMAND_LONG, mav.MAVLINK_MSG_ID_COMMAND_INT] * 4

    def _encoder(self, sysid: int):
        enc = self.encoders.get(sysid)
        if enc is None:
            enc = self.encoders[sysid] = mav.MAVLink(None, sysid, self.rng.randrange(256))
        return enc

    def _int(self, kind: str) -> int:
        lo, hi = INT_RANGES[kind]
        r = self.rng.random()
        if r < 0.4:
            return self.rng.choice((lo, hi, 0, 1, hi // 2, lo + 1, hi - 1))
        return self.rng.randint(lo, hi)

    def _float(self, kind: str) -> float:
        r = self.rng.random()
        if r < 0.5:
            return self.rng.choice(DOUBLE_EXTREMES if kind == "double" else FLOAT_EXTREMES)
        if r < 0.8:
            return self.rng.uniform(-2.0, 10.0)
        return self.rng.uniform(-1e6, 1e6)

    def _text(self, n: int) -> bytes:
        r = self.rng.random()
        if r < 0.2:
            return b""
        if r < 0.4:
            return self.rng.choice(PARAM_NAMES).encode()
        if r < 0.6:
            return bytes(self.rng.randrange(256) for _ in range(n + 5))  # overlong: the encoder truncates
        return bytes(self.rng.randrange(32, 127) for _ in range(self.rng.randrange(1, n + 1)))

    def _value(self, name: str, kind: str, length: int, msgid: int):
        if kind == "char":
            return self._text(length)
        if length:
            return [self._value(name, kind, 0, msgid) for _ in range(length)]
        v = self._special(name, kind, msgid)
        if kind in INT_RANGES and not INT_RANGES[kind][0] <= v <= INT_RANGES[kind][1]:
            return self._int(kind)
        return v

    def _special(self, name: str, kind: str, msgid: int):
        """Values that get past the first checks (our target ids, real commands, small sequence numbers)."""
        rng = self.rng
        if name == "target_system" or name == "target":
            return rng.choice((VEHICLE, VEHICLE, VEHICLE, 0, self._int(kind)))
        if name == "target_component":
            return rng.choice((1, 1, 1, 0, self._int(kind)))
        if name == "command" and msgid in (mav.MAVLINK_MSG_ID_COMMAND_LONG, mav.MAVLINK_MSG_ID_COMMAND_INT):
            return rng.choice(COMMAND_IDS) if rng.random() < 0.8 else self._int(kind)
        if name == "command" and msgid in (mav.MAVLINK_MSG_ID_MISSION_ITEM, mav.MAVLINK_MSG_ID_MISSION_ITEM_INT):
            return rng.choice(ITEM_COMMANDS) if rng.random() < 0.8 else self._int(kind)
        if name == "mission_type":
            return rng.choice((0, 0, 0, 1, 2, 255, self._int(kind)))
        if name in ("seq", "count") and rng.random() < 0.7:
            return rng.randrange(4)
        if name in ("frame", "coordinate_frame") and rng.random() < 0.7:
            return rng.choice((0, 1, 2, 3, 6, 8, 12))
        if name == "param_index" and rng.random() < 0.5:
            return rng.randrange(-1, len(SPECS) + 1)
        return self._float(kind) if kind in ("float", "double") else self._int(kind)

    def message(self, msgid: int):
        cls = MESSAGES[msgid]
        # array_lengths is in wire order; orders maps a field's declared position to its wire position
        args = [self._value(n, k, cls.array_lengths[cls.orders[i]], msgid)
                for i, (n, k) in enumerate(zip(cls.fieldnames, cls.fieldtypes, strict=True))]
        return cls(*args)

    def frame(self, sysid: int, msgid: int | None = None) -> tuple[int, bytes]:
        if msgid is None:
            msgid = self.rng.choice(self.ids if self.rng.random() < 0.5 else self.handled)
        return msgid, self.message(msgid).pack(self._encoder(sysid))

    def upload(self, sysid: int) -> list[bytes]:
        """A mission upload with random items, in order, so the items reach the plan checks."""
        n = self.rng.randrange(1, 5)
        mt = self.rng.choice((0, 0, 0, 1, 2))
        enc = self._encoder(sysid)
        out = [mav.MAVLink_mission_count_message(VEHICLE, 1, n, mt).pack(enc)]
        for k in range(n):
            m = self.message(self.rng.choice((mav.MAVLINK_MSG_ID_MISSION_ITEM_INT, mav.MAVLINK_MSG_ID_MISSION_ITEM)))
            m.seq, m.target_system, m.target_component, m.mission_type = k, VEHICLE, 1, mt
            out.append(m.pack(enc))
        return out

    def rtl(self, sysid: int) -> bytes:
        """RETURN_TO_LAUNCH: the owner starts the return plan it has just uploaded."""
        m = mav.MAVLink_command_long_message(VEHICLE, 1, mav.MAV_CMD_NAV_RETURN_TO_LAUNCH, 0, 0, 0, 0, 0, 0, 0, 0)
        return m.pack(self._encoder(sysid))

    def garble(self, frame: bytes) -> bytes:
        """Truncated, bit-flipped, glued to garbage or to another frame."""
        rng, b = self.rng, bytearray(frame)
        r = rng.random()
        if r < 0.3:
            return bytes(b[:rng.randrange(1, len(b))])
        if r < 0.6:
            for _ in range(rng.randrange(1, 4)):
                b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
            return bytes(b)
        if r < 0.8:
            return bytes(rng.randrange(256) for _ in range(rng.randrange(1, 20))) + frame
        return frame[:len(frame) // 2] + frame


class Fuzzer:
    """A vehicle owned by station 255 (with a plan, armed), fed generated frames."""

    def __init__(self, seed: int) -> None:
        self.seed = seed
        self.gen = Generator(seed)
        self.report = Report()
        self.pair = self._owned_pair(seed)

    @staticmethod
    def _owned_pair(seed: int) -> Pair:
        return Pair(seed=seed % 1000 + 1).take_control("rtl:30 | loiter:5 | launch")

    def _watch(self) -> None:
        """Record every message id the vehicle dispatches."""
        ep, reached = self.pair.endpoint, self.report.reached
        handle = ep.handle

        def watched(m, t):
            if m.get_type() != "BAD_DATA":
                reached.add(m.get_msgId())
            handle(m, t)

        ep.handle = watched

    def _feed(self, data: bytes) -> bool:
        pair = self.pair
        try:
            pair.endpoint.receive(data, pair.t)
        except Exception as e:  # noqa: BLE001 - the property under test
            self.report.crashes.append(f"receive raised {type(e).__name__}: {e} on {data.hex()}")
            return False
        return True

    def _step(self) -> None:
        try:
            self.pair.step()
        except Exception as e:  # noqa: BLE001 - the property under test
            self.report.crashes.append(f"tick raised {type(e).__name__}: {e}")

    def _faults(self, before: tuple[int, int], data: bytes) -> None:
        if self._fault_count() != before:
            self.report.crashes.append(f"a handler or the return service faulted on {data.hex()}")

    def _fault_count(self) -> tuple[int, int]:
        """Faults the vehicle contained (a handler or the return service raised): still bugs to report."""
        return self.pair.endpoint.counters.handler_faults, self.pair.vehicle.returns.faults

    def run(self, frames: int, owner_share: float = 0.2, every: int = 200, stop_on_first: bool = True) -> Report:
        """Feed ``frames`` frames; the vehicle ticks once every ``every`` frames. Non-owner frames are checked
        one by one against the state snapshot; then a share of owner frames (and fresh owned vehicles when the
        owner has given its vehicle away) checks only that nothing crashes."""
        self._watch()
        rep, gen, rng = self.report, self.gen, self.gen.rng
        n_owner = int(frames * owner_share)
        others = [s for s in range(1, 255) if s != VEHICLE]
        while rep.frames < frames - n_owner and not (stop_on_first and (rep.crashes or rep.state_changes)):
            sysid = rng.choice(others)
            batch = gen.upload(sysid) if rng.random() < 0.02 else [gen.frame(sysid)[1]]
            for data in batch:
                if rng.random() < 0.1:
                    data = gen.garble(data)
                    rep.garbled += 1
                before, faults = snapshot(self.pair), self._fault_count()
                if self._feed(data) and snapshot(self.pair) != before:
                    rep.state_changes.append(f"frame from {sysid} changed the state: {data.hex()}")
                self._faults(faults, data)
                rep.frames += 1
                if rep.frames % every == 0:
                    self._step()
        if not (stop_on_first and (rep.crashes or rep.state_changes)):
            self._sweep_ids(others)
        while rep.frames < frames and not (stop_on_first and (rep.crashes or rep.state_changes)):
            start_return = rng.random() < 0.05
            batch = gen.upload(OWNER) + [gen.rtl(OWNER)] if start_return else [gen.frame(OWNER)[1]]
            for data in batch:
                faults = self._fault_count()
                self._feed(data)
                self._faults(faults, data)
                rep.frames += 1
                rep.owner_frames += 1
                if rep.frames % every == 0:
                    self._step()
            if start_return:  # the uploaded plan runs: its blocks start and step
                faults = self._fault_count()
                for _ in range(3):
                    self._step()
                if self._fault_count() != faults:
                    self.report.crashes.append(f"the return of plan {self.pair.vehicle.plan_items} faulted")
        return rep

    def _sweep_ids(self, others: list[int]) -> None:
        """Every message id once more from a non-owner, so none is left to chance."""
        for msgid in MESSAGES:
            before = snapshot(self.pair)
            data = self.gen.frame(self.gen.rng.choice(others), msgid)[1]
            if self._feed(data) and snapshot(self.pair) != before:
                self.report.state_changes.append(f"message {msgid} changed the state: {data.hex()}")
            self.report.frames += 1
