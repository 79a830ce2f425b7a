"""Message signing on one link (docs/architecture.md §4.1): the gate in front of every service, key rotation, the
timestamp file.

``link.signing`` is the pure core (a frame judged against a key and the streams seen); this service is its state on
one component: the installed key, the streams accepted so far, the outgoing timestamp (never backwards, saved to
the key store every STAMP_SAVE_EVERY seconds and at shutdown so a reboot never reuses one), and the gate. With a
key installed, a frame that is not signed with it may still *read* (``ACCESS``: READ) but never *act*: a
state-changing message from it is dropped, counted and announced at most every REJECT_NOTICE_GAP seconds, never
answered (a refusal ACK would land on the owner's own pending command when the forger uses the owner's sysid).
SETUP_SIGNING rotates the key, only over a link already signed with the installed one.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from enum import Enum

from link.signing import MAX_TIMESTAMP, Key, SigningVerdict, Streams, advance, enable, sim_stamp, timestamp_of
from vehicle.keystore import STAMP_SAVE_EVERY, KeyStore, boot_stamp
from vehicle.port import EventQueue
from vehicle.services.base import Outbox, Service, Source, Throttle, handles, mav

REJECT_NOTICE_GAP = 2.0  # s between STATUSTEXTs about refused frames


class Access(Enum):
    """What a message does, for the signing gate."""

    READ = "read"  # asks for information: answered to anyone, signed or not
    ACT = "act"  # changes vehicle state: with a key installed, only from frames signed with it
    KEY = "key"  # SETUP_SIGNING: judges its own signature and always answers why


# The gate's one table: what each message does, messages by name and commands (COMMAND_LONG and COMMAND_INT) by
# id. Anything not listed acts. With a key installed an unsigned station can watch, never act.
ACCESS: dict[str | int, Access] = {
    "HEARTBEAT": Access.READ,  # peer discovery; an unsigned one is never "the owner heard"
    "PARAM_REQUEST_LIST": Access.READ,
    "PARAM_REQUEST_READ": Access.READ,
    "MISSION_REQUEST_LIST": Access.READ,
    "MISSION_REQUEST_INT": Access.READ,
    "MISSION_REQUEST": Access.READ,
    "MISSION_ACK": Access.READ,  # ends a download; cancels an upload only when trusted (the mission service)
    "SETUP_SIGNING": Access.KEY,
    mav.MAV_CMD_REQUEST_MESSAGE: Access.READ,  # one message, once (a stream is SET_MESSAGE_INTERVAL: acts)
    mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: Access.READ,
    mav.MAV_CMD_GET_HOME_POSITION: Access.READ,
}


def access(m) -> Access:
    kind = m.get_type()
    if kind in ("COMMAND_LONG", "COMMAND_INT"):
        return ACCESS.get(m.command, Access.ACT)
    return ACCESS.get(kind, Access.ACT)


class Signing(Service):
    """The signing state of one component's link. No key (``key`` None): signing is off and every frame trusted.

    ``keystore`` (which also keeps the key and the timestamp on disk) or ``key`` turns it on; ``stamp(t)`` is the
    signing clock in 10 µs units since 2015 (the wall clock on a real vehicle, simulated time in the simulator)."""

    def __init__(self, out: Outbox, vehicle: EventQueue, boot_t: float = 0.0,
                 stamp: Callable[[float], int] = sim_stamp, *, key: Key | None = None, keystore: KeyStore | None = None,
                 verdicts: Counter | None = None) -> None:
        self.out = out
        self.vehicle = vehicle
        self.stamp = stamp
        self.key: Key | None = None
        self.keystore = keystore
        self.streams = Streams()
        self.verdicts: Counter = Counter() if verdicts is None else verdicts  # frames judged, per verdict
        self.stamp_saved_at = boot_t
        self.notices = Throttle(REJECT_NOTICE_GAP)
        self.refused_since_notice = 0
        if keystore is not None:
            self.install_key(keystore.key, boot_stamp(keystore.saved_stamp, stamp(boot_t)))
        elif key is not None:
            self.install_key(key, stamp(boot_t))

    def install_key(self, key: Key, timestamp: int) -> None:
        """Sign everything sent from now on and accept state changes only from frames signed with ``key``."""
        self.key = key
        enable(self.out.mav, key, timestamp)
        self.vehicle.bind_key()

    def timestamp(self, t: float) -> int:
        """Our signing timestamp at ``t``: the clock, or further on if we already used (or accepted) later."""
        return advance(self.out.mav, self.stamp(t)) if self.key is not None else 0

    def save_stamp(self, t: float) -> None:
        """Persist the signing timestamp so a reboot never reuses one (a failure is announced, not fatal)."""
        if self.keystore is None or self.key is None:
            return
        self.stamp_saved_at = t
        try:
            self.keystore.save_stamp(self.timestamp(t))
        except OSError as e:
            self.out.statustext(f"signing timestamp not saved: {e.strerror or e}", mav.MAV_SEVERITY_ERROR)

    def check(self, m, sender: int, t: float) -> bool | None:
        """The gate, with a key installed: whether the frame is trusted, or None if it is refused (dropped)."""
        frame = bytes(m.get_msgbuf())
        self.streams, verdict = self.streams.verify(self.key, frame, self.timestamp(t))
        self.verdicts[verdict] += 1
        if verdict is SigningVerdict.ACCEPT:
            advance(self.out.mav, timestamp_of(frame) or 0)  # the spec: continue from the newest timestamp accepted
            return True
        if access(m) is not Access.ACT:
            return False
        self._refuse(m, verdict, sender, t)
        return None

    def _refuse(self, m, verdict: SigningVerdict, sender: int, t: float) -> None:
        self.vehicle.refused()
        self.refused_since_notice += 1
        if not self.notices.due("refused", t):
            return
        more = self.refused_since_notice - 1
        self.refused_since_notice = 0
        self.out.statustext(f"{verdict.value} {m.get_type()} from {sender} refused"
                            + (f" (+{more} more since the last notice)" if more else ""), mav.MAV_SEVERITY_WARNING)

    @handles("SETUP_SIGNING")
    def _on_setup_signing(self, m, src: Source, t: float) -> None:
        """Key rotation, only over a link already signed with the installed key; answered either way."""
        warn = mav.MAV_SEVERITY_WARNING
        if self.key is None:
            self.out.statustext("signing setup refused: no key installed (a key is never installed over the link; "
                                "start the vehicle with --key FILE)", warn)
            return
        if not src.trusted:
            self.out.statustext(f"signing setup from {src.sysid} refused: not signed with the installed key", warn)
            return
        secret = bytes(bytearray(m.secret_key))
        if len(secret) != 32 or not any(secret):
            self.out.statustext("signing setup refused: signing cannot be switched off over the link", warn)
            return
        if not 0 <= m.initial_timestamp <= MAX_TIMESTAMP:
            self.out.statustext("signing setup refused: initial timestamp outside 48 bits", warn)
            return
        key = Key(secret)
        if self.keystore is not None:
            try:
                self.keystore.save_key(key)
            except OSError as e:
                self.out.statustext(f"signing setup failed, key kept: cannot save the new key ({e.strerror or e})",
                                    mav.MAV_SEVERITY_ERROR)
                return
        self.install_key(key, max(self.timestamp(t), int(m.initial_timestamp)))
        self.save_stamp(t)
        self.out.statustext(f"signing key changed by GCS {src.sysid} (key id {key.fingerprint})",
                            mav.MAV_SEVERITY_NOTICE)

    def tick(self, t: float) -> None:
        """Keep the outgoing timestamp up with the clock; save it every STAMP_SAVE_EVERY seconds."""
        if self.key is None:
            return
        self.timestamp(t)
        if t - self.stamp_saved_at >= STAMP_SAVE_EVERY:
            self.save_stamp(t)
