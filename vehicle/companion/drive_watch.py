"""The owner's drive of the autopilot, watched from the companion: the dead-man (LNK_HOLD_S) over the owner's
setpoints, the owner's own rhythm it waits on, and PX4's Offboard drive that went to Hold and resumes on the owner's
next setpoint.

The native vehicle drops a teleop setpoint 0.5 s after its stream stops; an autopilot drives on to the owner's last
target for as long as nobody says otherwise, which before the dead-man was the whole LNK_TIMEOUT before the return
took it back (issue 28). This is the vehicle side of the companion beside its routing (``vehicle.companion.app``):
what the owner's forwarded frames and the lease book say, turned into a stop or a resume through the driver.
"""

from __future__ import annotations

from collections import deque

from vehicle.companion.autopilot import AutopilotDriver
from vehicle.lease import Holder, LeaseBook

# the owner's drive of the autopilot in GUIDED: what the dead-man watches (MANUAL_CONTROL and RC override have the
# autopilot's own override timeout, RC_OVERRIDE_TIME)
SETPOINTS = frozenset(("SET_POSITION_TARGET_LOCAL_NED", "SET_POSITION_TARGET_GLOBAL_INT"))
STOP_RESEND = 1.0  # s between repeated stops while the owner stays silent (one may be lost on the wire)
HOLD_GAPS = 1.0  # the dead-man waits no shorter than the owner's longest recent gap between packets
RHYTHM_S = 5.0  # s: the owner's gaps between packets over this long are its rhythm
STREAM_S = 2.5  # s: the owner counts as driving with setpoints if it sent one this long before its last packet


def drive_held(t: float, setpoint_at: float | None, owner_heard: float | None, hold_s: float,
               rhythm: float) -> bool:
    """The companion's dead-man (LNK_HOLD_S): the owner was driving the autopilot with setpoints (one within
    STREAM_S of its last packet) and has been silent ``hold_after(hold_s, rhythm)``.

    Silence (no packet at all, heartbeats included) is the test, so an owner is not held while its 1 Hz heartbeat
    arrives (LNK_HOLD_S 1 s by default, a heartbeat's period; a stick let go while the heartbeat goes on is the
    autopilot's own business, its velocity targets time out in 3 s). Below that a fixed time trips on sparse senders
    (measured: at 0.7 s the scripted GUIDED operator, a heartbeat a second and a target a metre, was stopped
    between its packets and never got going); above it the owner's own rhythm (``rhythm``: its longest gap
    between its packets over the last RHYTHM_S, the radio's holes taken out: ``DriveWatch.rhythm``) lets an owner
    that sends sparsely drive. Measured on companion.toml's five worlds (50 trials each): LNK_HOLD_S 1.25 fixed,
    P95 to link 6.3-17.2 s; 1.25 with 1.25x the rhythm, 6.3-20.8 s; 1 with the rhythm counting the radio's holes,
    6.3-13.3 s; 1 with the owner's own rhythm, see the README's companion table. An owner that sent
    one goal and then only its heartbeat is not streaming: the autopilot drives on to the goal, and LNK_TIMEOUT
    governs."""
    if hold_s <= 0 or setpoint_at is None or owner_heard is None or owner_heard - setpoint_at > STREAM_S:
        return False
    return t - owner_heard >= hold_after(hold_s, rhythm)


def hold_after(hold_s: float, rhythm: float) -> float:
    """Seconds of the owner's silence after which the dead-man holds the drive (see ``drive_held``)."""
    return max(hold_s, HOLD_GAPS * rhythm)


class DriveWatch:
    """The dead-man, the owner's rhythm and PX4's held drive (see the module docstring), acting through
    ``driver``."""

    def __init__(self, driver: AutopilotDriver) -> None:
        self.driver = driver
        self.setpoint_at: float | None = None  # the owner's last setpoint forwarded to the autopilot
        self.gaps: deque[tuple[float, float]] = deque()  # (arrival, gap before it) of the owner's recent packets
        self.heard_at: float | None = None  # the owner's last packet, as the rhythm last saw it
        self.heard_seq: int | None = None  # its unwrapped sequence number (None: not measured)
        self.stopped_at: float | None = None  # the dead-man's last stop (None: not holding)
        # PX4: the owner's Offboard drive went to Hold (the dead-man, or PX4's own Offboard loss) and its next
        # setpoint asks for Offboard again (``resume_drive``); the mode last seen, and a ground mode change's time
        self.held_drive = False
        self.last_mode: int | None = None
        self.ground_mode_at: float | None = None

    # ----- what the owner did, as forwarded to the autopilot ---------------------------------------------------
    def mode_changed(self, t: float) -> None:
        """The owner's mode change reached the autopilot: the mode is its choice, nothing held to resume."""
        self.held_drive, self.ground_mode_at = False, t

    def setpoint(self, t: float) -> None:
        """The owner's setpoint reached the autopilot: it drives again (PX4: out of a Hold nobody asked for)."""
        self.setpoint_at, self.stopped_at = t, None
        if self.held_drive:
            self.resume_drive(t)

    def resume_drive(self, t: float) -> None:
        """The owner's setpoint arrived (forwarded: it holds the current lease) while its Offboard drive stands
        in a Hold it did not ask for: Offboard again, as ArduPilot drives again on the owner's next target after
        the dead-man's stop. The companion knows whose lease is current; the owner's station, a radio hop away,
        may not (a mode change from it over a return that began meanwhile would take the lease from the return)."""
        d = self.driver
        if d.seen.mode == d.rules.hold and not d.engaged:
            self.held_drive = False
            d.resume(t)

    # ----- each tick ------------------------------------------------------------------------------------------
    def tick(self, t: float, book: LeaseBook, returning: bool, hold_s: float, timeout: float,
             autopilot_lost: bool) -> str | None:
        """The rhythm brought up to date, the dead-man (unless a return holds the lease) and PX4's held drive;
        the dead-man's notice when it first stops the drive (None: nothing to say)."""
        rhythm = self.rhythm(book.link.last_heard, book.link.delivery.newest, timeout)
        said = None if returning else self.dead_man(t, rhythm, book, hold_s, autopilot_lost)
        self.watch_held(t, book, returning)
        return said

    def dead_man(self, t: float, rhythm: float, book: LeaseBook, hold_s: float, autopilot_lost: bool) -> str | None:
        """Stop the autopilot's drive once the owner driving it with setpoints has fallen silent (``drive_held``):
        a zero-velocity target, repeated every STOP_RESEND s while the silence lasts. The owner's next setpoint
        drives again; a return that follows finds the autopilot in GUIDED and standing (PX4: in Hold, which the
        return leaves for Offboard once its own stream runs; ``AutopilotDriver.stop``). The notice to give when
        the drive is first stopped, else None."""
        d = self.driver
        heard = book.link.last_heard
        cur = book.current
        if (cur is None or cur.holder is not Holder.OPERATOR or not d.armed or autopilot_lost
                or not drive_held(t, self.setpoint_at, heard, hold_s, rhythm)):
            return None
        if self.stopped_at is not None and t - self.stopped_at < STOP_RESEND:
            return None
        if not d.stop(t):
            return None
        self.held_drive = self.held_drive or d.rules.stop_holds  # (PX4: the owner's next setpoint resumes)
        first = self.stopped_at is None
        self.stopped_at = t
        if not first:
            return None
        return f"owner silent {t - (heard or t):.1f} s: the autopilot's drive stopped (LNK_HOLD_S)"

    def rhythm(self, heard: float | None, seq: int | None, timeout: float) -> float:
        """The owner's own longest spacing between packets over the RHYTHM_S before its last one (0: none
        known): each gap between two packets heard, divided by the packets it sent in it (their MAVLink sequence
        numbers, ``seq`` the newest heard; 1 where they are not measured). A hole the radio made is not the
        owner's rhythm: the packets it swallowed were sent, and counting the hole let the autopilot drive on to a
        stale target at the fringe (issue 28, the open field: 6-12 m deeper before the loss, a longer way back). A
        gap of LNK_TIMEOUT or more was a loss, not a rhythm at all."""
        if heard is None:
            return 0.0
        gaps = self.gaps
        if heard != self.heard_at:
            if self.heard_at is not None and heard - self.heard_at < timeout:
                sent = 1 if seq is None or self.heard_seq is None else seq - self.heard_seq
                if sent > 0:
                    gaps.append((heard, (heard - self.heard_at) / sent))
            self.heard_at, self.heard_seq = heard, seq
            while gaps and gaps[0][0] < heard - RHYTHM_S:
                gaps.popleft()
        return max((g for _, g in gaps), default=0.0)

    def watch_held(self, t: float, book: LeaseBook, returning: bool) -> None:
        """PX4: note when the owner's Offboard drive went to Hold without anyone on the ground asking (PX4's
        Offboard loss: the owner's stream silent for COM_OF_LOSS_T), so that its next setpoint resumes it
        (``resume_drive``); forget it once the rover is in any other mode or a return holds the lease."""
        d = self.driver
        mode, rules = d.seen.mode, d.rules
        cur = book.current
        if (rules.stop_holds and not returning and self.last_mode == rules.drive and mode == rules.hold
                and cur is not None and cur.holder is Holder.OPERATOR and cur.claimed and self.setpoint_at is not None
                and t - self.setpoint_at <= STREAM_S
                and (self.ground_mode_at is None or t - self.ground_mode_at > STREAM_S)):
            self.held_drive = True
        if returning or mode not in (rules.drive, rules.hold):
            self.held_drive = False
        self.last_mode = mode
