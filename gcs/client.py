"""A blocking ground-station client over UDP: ``GroundStation`` plus a socket, the wall clock and waits.

    with Client("udpin:127.0.0.1:14550") as c:
        c.connect()
        c.acquire()
        c.upload(parse_spec("rtl:50 | loiter:30 | launch"))
        c.drive_velocity(1.0, 0.0, seconds=5)

Every wait has a timeout and raises ``GcsError`` saying what did not happen.
"""

from __future__ import annotations

import secrets
import time
from collections.abc import Callable
from pathlib import Path

from gcs.station import GroundStation, Pending, Transfer, mav
from link.mission import Item
from link.parameters import ParamError, format_parm, parse_parm
from link.signing import Key, stamp_from_unix
from link.transports import UdpTransport

POLL = 0.005


class GcsError(RuntimeError):
    pass


def parse_url(url: str) -> tuple[tuple[str, int], tuple[tuple[str, int], ...]]:
    """``udpin:HOST:PORT`` (listen there) or ``udpout:HOST:PORT`` (send there from an ephemeral port)."""
    try:
        kind, host, port = url.split(":")
        addr = (host, int(port))
    except ValueError:
        raise GcsError(f"bad connection {url!r}: expected udpin:HOST:PORT or udpout:HOST:PORT") from None
    if kind == "udpin":
        return addr, ()
    if kind == "udpout":
        return ("0.0.0.0" if host != "127.0.0.1" else "127.0.0.1", 0), (addr,)
    raise GcsError(f"bad connection {url!r}: expected udpin:HOST:PORT or udpout:HOST:PORT")


class Client:
    def __init__(self, url: str = "udpin:127.0.0.1:14550", sysid: int = 255, compid: int = 190,
                 target: int = 1, clock: Callable[[], float] = time.monotonic, key: Key | None = None,
                 wall: Callable[[], float] = time.time, sleep: Callable[[float], None] = time.sleep,
                 target_comp: int = 1) -> None:
        """With ``key`` everything sent is signed; timestamps follow the wall clock, on a link id of this session's
        own, so two sessions of one station (``gcs watch`` beside ``gcs rtl``) are two streams, not replays.
        ``clock`` and ``sleep`` are the time the waits run on (a test passes simulated ones). ``target_comp``: the
        component addressed, 191 for returnlink running as a companion beside an autopilot."""
        bind, peers = parse_url(url)
        try:
            self.transport = UdpTransport(bind, peers)
        except OSError as e:
            raise GcsError(f"cannot open {url}: {e}") from None
        self.clock, self.sleep = clock, sleep
        self.t0 = clock()
        wall0 = wall()
        self.gs = GroundStation(sysid, compid, target, target_comp, key=key, link_id=secrets.randbelow(256),
                                stamp=lambda t: stamp_from_unix(wall0 + t))

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        self.transport.close()

    @property
    def now(self) -> float:
        return self.clock() - self.t0

    def pump(self, seconds: float = 0.0) -> None:
        """Exchange frames for ``seconds`` (at least once)."""
        end = self.now + seconds
        while True:
            t = self.now
            for data, _ in self.transport.receive():
                self.gs.feed(data, t)
            for frame in self.gs.tick(t):
                self.transport.send(frame)
            if self.now >= end:
                return
            self.sleep(POLL)

    def wait_for(self, predicate: Callable[[], bool], timeout: float, what: str) -> None:
        end = self.now + timeout
        while not predicate():
            if self.now >= end:
                raise GcsError(f"timed out after {timeout:g} s waiting for {what}")
            self.pump()
            self.sleep(POLL)

    # ----- connection and status -----------------------------------------------------------------------------
    def connect(self, timeout: float = 10.0) -> None:
        """Wait for the vehicle's HEARTBEAT (who it is, armed or not) and its LEASE_STATUS: a report printed
        before both have arrived would show an anonymous, disarmed vehicle that does not exist."""
        self.gs.t = self.now
        try:
            self.wait_for(lambda: self.gs.vehicle.sysid != 0 and self.gs.vehicle.status is not None,
                          timeout, "a returnlink vehicle (HEARTBEAT and LEASE_STATUS)")
        except GcsError as e:
            refused = sum(self.gs.refused.values())
            if refused:
                kinds = ", ".join(f"{n} {v.value}" for v, n in self.gs.refused.items())
                why = f"{refused} frames from the vehicle were not signed with this key ({kinds})"
                raise GcsError(f"{e}; {why}") from None
            raise

    def text_since(self, t: float, *needles: str) -> str | None:
        """The newest STATUSTEXT received at or after ``t`` that contains every needle."""
        for at, text in reversed(self.gs.texts):
            if at < t:
                return None
            if all(n in text for n in needles):
                return text
        return None

    def call(self, pending: Pending, timeout: float = 6.0, what: str = "") -> Pending:
        self.wait_for(lambda: pending.done, timeout, f"an answer to {what or pending.command}")
        if not pending.ok:
            reason = self._last_refusal()
            raise GcsError(f"{what or pending.command} refused: {pending.result_name}" + (f" ({reason})"
                                                                                          if reason else ""))
        return pending

    def _last_refusal(self) -> str:
        self.pump(0.1)
        texts = [x for _, x in self.gs.texts[-5:] if "refused" in x or "not" in x]
        return texts[-1] if texts else ""

    def acquire(self, allow_takeover: bool = False) -> int:
        p = self.call(self.gs.acquire(allow_takeover), what="operator control request")
        self.wait_for(lambda: self.gs.vehicle.status is not None and self.gs.vehicle.status.epoch == p.param2,
                      3.0, "the new epoch in LEASE_STATUS")
        return p.param2

    def release(self) -> None:
        self.call(self.gs.release(), what="release")

    def claim(self, index: int = -1) -> int:
        return self.call(self.gs.claim(index), what="lease claim").param2

    def expire(self, index: int | None = None) -> None:
        self.call(self.gs.expire(index), what="lease expire")

    def rtl(self) -> None:
        self.call(self.gs.rtl(), what="return")

    def hold(self) -> None:
        self.call(self.gs.hold(), what="hold")

    def arm(self, armed: bool = True) -> None:
        self.call(self.gs.arm(armed), what="arm" if armed else "disarm")

    # ----- driving -------------------------------------------------------------------------------------------
    def drive_velocity(self, vn: float, ve: float, seconds: float) -> None:
        """Stream a NED velocity for ``seconds``, then stop; GcsError when the vehicle refused the setpoints."""
        since = self.now
        self.gs.drive_velocity(vn, ve)
        self.pump(seconds)
        self.stop_driving()
        self.check_teleop(since)

    def drive_manual(self, x: float, r: float, seconds: float) -> None:
        """MANUAL_CONTROL-style: forward ``x`` and turn ``r``, each -1..1 of the vehicle's maximum."""
        since = self.now
        self.gs.drive_manual(x, r)
        self.pump(seconds)
        self.stop_driving()
        self.check_teleop(since)

    def stop_driving(self) -> None:
        """A zero setpoint for a moment (so the vehicle stops now, not at its teleop time-out), then silence."""
        kind = self.gs.teleop[0] if self.gs.teleop else "velocity"
        if kind == "manual":
            self.gs.drive_manual(0.0, 0.0)
        else:
            self.gs.stop()
        self.pump(0.3)
        self.gs.stop_streaming()

    def check_teleop(self, since: float) -> None:
        """Teleop setpoints are a stream without acknowledgements: the vehicle refuses them with a rate-limited
        STATUSTEXT. Raise GcsError naming the refusal (and the way out when the lease awaits a claim)."""
        self.pump(0.2)
        text = self.text_since(since, f"teleop from {self.gs.sysid} refused")
        if text is None:
            return
        st = self.gs.vehicle.status
        hint = ""
        if st is not None and st.state_name == "AWAITING_CLAIM":
            hint = f"; the vehicle is AWAITING_CLAIM: run `claim` to take lease [{st.epoch},{st.current}] first"
        raise GcsError(f"drive refused: {text}{hint}")

    # ----- plans ---------------------------------------------------------------------------------------------
    def _transfer(self, tr: Transfer, timeout: float, what: str) -> Transfer:
        self.wait_for(lambda: tr.done, timeout, what)
        if not tr.ok:
            name = mav.enums["MAV_MISSION_RESULT"].get(tr.result) if tr.result is not None else None
            reason = self._last_refusal()
            raise GcsError(f"{what} failed: {name.name if name else 'no answer'}" + (f" ({reason})" if reason
                                                                                   else ""))
        return tr

    def upload(self, items: list[Item], mission_type: int = 0, timeout: float = 15.0) -> None:
        self._transfer(self.gs.upload(items, mission_type), timeout, "plan upload")

    def download(self, mission_type: int = 0, timeout: float = 15.0) -> list[Item]:
        return self._transfer(self.gs.download(mission_type), timeout, "plan download").items

    def clear(self, mission_type: int = 0, timeout: float = 6.0) -> None:
        self._transfer(self.gs.clear(mission_type), timeout, "plan clear")

    # ----- files ---------------------------------------------------------------------------------------------
    def fetch(self, path: str, timeout: float = 30.0) -> bytes:
        """The vehicle's file ``path`` (MAVLink FTP), whole; GcsError naming why if it cannot be had."""
        d = self.gs.fetch(path)
        self.wait_for(lambda: d.done, timeout, f"file {path}")
        if not d.ok:
            raise GcsError(f"file {path}: {d.error}")
        return bytes(d.data)

    # ----- parameters ----------------------------------------------------------------------------------------
    def param_get(self, name: str, timeout: float = 3.0) -> float:
        since = self.now
        self.gs.vehicle.params.pop(name, None)
        self.gs.param_request(name)
        self.wait_for(lambda: name in self.gs.vehicle.params or self._unknown_param(since, name), timeout,
                      f"parameter {name}")
        if name not in self.gs.vehicle.params:
            raise GcsError(f"unknown parameter {name!r}: the vehicle has no parameter of that name")
        return self.gs.vehicle.params[name]

    def _unknown_param(self, since: float, name: str) -> bool:
        """The vehicle answers a read or set of a name it does not have with STATUSTEXT "no parameter 'NAME'"."""
        return self.text_since(since, f"no parameter {name!r}") is not None

    def param_set(self, name: str, value: float, timeout: float = 3.0) -> float:
        """Set and confirm: the vehicle echoes the stored value, which is the old one if it refused."""
        since = self.now
        for _ in range(3):
            self.gs.vehicle.params.pop(name, None)
            self.gs.param_set(name, value)
            try:
                self.wait_for(lambda: name in self.gs.vehicle.params or self._unknown_param(since, name),
                              timeout / 3, f"parameter {name}")
                break
            except GcsError:
                continue
        else:
            raise GcsError(f"no answer setting {name}")
        if name not in self.gs.vehicle.params:
            raise GcsError(f"unknown parameter {name!r}: the vehicle has no parameter of that name")
        got = self.gs.vehicle.params[name]
        if not abs(got - value) <= 1e-6 * max(1.0, abs(value)):  # NaN never matches: a refusal, not a success
            raise GcsError(f"{name} refused, still {got:g}" + (f" ({r})" if (r := self._last_refusal()) else ""))
        return got

    def param_all(self, timeout: float = 5.0) -> dict[str, float]:
        self.gs.vehicle.params.clear()
        self.gs.param_request_all()
        self.wait_for(lambda: self.gs.vehicle.param_count > 0
                      and len(self.gs.vehicle.params) >= self.gs.vehicle.param_count, timeout, "all parameters")
        return dict(self.gs.vehicle.params)

    def param_save(self, path: Path) -> int:
        values = self.param_all()
        path.write_text(format_parm(values), encoding="utf-8")
        return len(values)

    def param_load(self, path: Path) -> int:
        try:
            values = parse_parm(path.read_text(encoding="utf-8"), str(path))
        except (OSError, ParamError) as e:
            raise GcsError(str(e)) from None
        for name, value in values.items():
            self.param_set(name, value)
        return len(values)
