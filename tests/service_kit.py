"""One microservice alone, frames in and frames out: a real vehicle on a simulated robot, the component's outbox,
and stations that build their frames with pymavlink's own encoder (so every frame has a real header and CRC).

    kit = Kit()
    params = ParamServer(kit.out, kit.vehicle)
    replies = kit.send(params, mav.MAVLink_param_request_list_message(1, 1))   # parsed messages out
"""

from __future__ import annotations

import numpy as np

from link.signing import Key, enable, sim_stamp
from sim.driver import SimDriver
from sim.scenario import load
from vehicle.app import Vehicle
from vehicle.params import load_defaults
from vehicle.services.base import Counters, Outbox, Service, Source, mav

OWNER = 255
STRANGER = 66


class Kit:
    def __init__(self, sysid: int = 1, compid: int = 1, scenario: str = "open") -> None:
        sc = load(scenario)
        self.driver = SimDriver(sc, "rover", np.random.default_rng(1))
        self.vehicle = Vehicle(self.driver, load_defaults(), sc.start, 0.0, seed=1)
        self.out = Outbox(sysid, compid)
        self.counters = Counters()
        self.parser = mav.MAVLink(None, 0, 0)
        self.parser.robust_parsing = True
        self.encoders: dict[tuple[int, int], object] = {}
        self.t = 0.0

    def encoder(self, sysid: int = OWNER, compid: int = 190, key: Key | None = None):
        """Station ``sysid``'s encoder (signing with ``key`` from the simulated clock's origin, if given)."""
        enc = self.encoders.get((sysid, compid, key))
        if enc is None:
            enc = self.encoders[(sysid, compid, key)] = mav.MAVLink(None, sysid, compid)
            if key is not None:
                enable(enc, key, sim_stamp(self.t))
        return enc

    def frame(self, msg, sysid: int = OWNER, compid: int = 190, key: Key | None = None) -> bytes:
        """``msg`` as a whole frame from station ``sysid``, signed with ``key`` if given."""
        return msg.pack(self.encoder(sysid, compid, key))

    def parse(self, data: bytes):
        msgs = self.parser.parse_buffer(data) or []
        assert len(msgs) == 1, msgs
        return msgs[0]

    def send(self, service: Service, msg, sysid: int = OWNER, compid: int = 190, trusted: bool = True,
             t: float | None = None) -> list:
        """Hand ``msg``, framed as station ``sysid`` sends it, to ``service``; what it answered, parsed."""
        m = self.parse(self.frame(msg, sysid, compid))
        service.handle(m, Source(sysid, compid, trusted), self.t if t is None else t)
        return self.replies()

    def replies(self) -> list:
        """Every frame the component produced since the last call, parsed."""
        return [self.parse(f) for f in self.out.take()]

    def take_control(self, sysid: int = OWNER) -> None:
        """Give station ``sysid`` the root lease, as REQUEST_OPERATOR_CONTROL would."""
        assert self.vehicle.operator_control(sysid, 190, self.t, True, allow_takeover=False).executes
        self.vehicle.events.clear()
        self.vehicle.notices.clear()


def command_long(command: int, *params: float, target: int = 1, component: int = 1):
    p = [*params, *[0.0] * (7 - len(params))]
    return mav.MAVLink_command_long_message(target, component, command, 0, *p)


def types(replies: list) -> list[str]:
    return [m.get_type() for m in replies]


def texts(replies: list) -> list[str]:
    """The STATUSTEXTs among ``replies``, chunks of one text (same non-zero id) joined."""
    out: list[str] = []
    last_id = 0
    for m in replies:
        if m.get_type() != "STATUSTEXT":
            continue
        if m.id and m.id == last_id:
            out[-1] += m.text
        else:
            out.append(m.text)
        last_id = m.id
    return out

