"""What the companion sends the autopilot whatever a return does: the backstop and the streams it reads.

The backstop: a HEARTBEAT from a ground-station system id (the autopilot's MAV_GCS_SYSID, read from it; PX4 counts
any GCS-type HEARTBEAT) at 1 Hz, sent only by a loop that ticks and is healthy. Ground stations' own heartbeats never
reach the autopilot, so a dead or hung companion ends in the autopilot's GCS failsafe (ArduPilot: FS_GCS_ENABLE,
FS_ACTION; PX4: NAV_DLL_ACT after COM_DL_LOSS_T).

The streams: the estimate's messages asked for at first contact and again whenever the position stream has slowed
(a ground station's REQUEST_DATA_STREAM resets the autopilot's rates on this very channel), the EKF origin and the
parameters the rules need until they are known. Pure apart from its counters: it says what is due.
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import ardupilotmega as apm

from vehicle.companion.observed import Observed
from vehicle.companion.rules import Rules

COMPANION_COMPID = apm.MAV_COMP_ID_ONBOARD_COMPUTER
KEEPALIVE_PERIOD = 1.0  # s between backstop heartbeats
STREAM_CHECK = 5.0  # s between checks that the position stream still runs at its rate


class Upkeep:
    """The backstop heartbeat and the stream requests (see the module docstring)."""

    def __init__(self) -> None:
        self.keepalive_enc = apm.MAVLink(None, 255, COMPANION_COMPID)  # its system id: the autopilot's GCS's
        self.next_keepalive = -math.inf
        self.next_stream_check = -math.inf
        self.streams_asked = False
        self.keepalives = 0  # sent, for the record

    def keepalive(self, t: float, healthy: bool, seen: Observed, rules: Rules):
        """The backstop HEARTBEAT due at ``t`` (None: not due, or the loop is not healthy), to be packed with
        ``keepalive_enc``."""
        if not healthy or t < self.next_keepalive:
            return None
        self.next_keepalive = t + KEEPALIVE_PERIOD
        gcs = next((int(seen.params[p]) for p in rules.gcs_sysid_params if p in seen.params), 255)
        self.keepalive_enc.srcSystem = gcs if 1 <= gcs <= 255 else 255
        self.keepalives += 1
        return self.keepalive_enc.heartbeat_encode(apm.MAV_TYPE_GCS, apm.MAV_AUTOPILOT_INVALID, 0, 0,
                                                   apm.MAV_STATE_ACTIVE)

    def requests(self, t: float, enc: apm.MAVLink, seen: Observed, rules: Rules) -> list:
        """The stream, origin and parameter requests due at ``t``, every STREAM_CHECK s (see the module
        docstring)."""
        if t < self.next_stream_check:
            return []
        self.next_stream_check = t + STREAM_CHECK
        assert seen.sysid is not None
        out = []
        wanted = 0.8 * 1e6 / rules.streams[apm.MAVLINK_MSG_ID_LOCAL_POSITION_NED]
        if not self.streams_asked or seen.rate(t) < wanted:
            out += [enc.command_long_encode(seen.sysid, seen.compid, apm.MAV_CMD_SET_MESSAGE_INTERVAL, 0, msgid,
                                            interval, 0, 0, 0, 0, 0) for msgid, interval in rules.streams.items()]
            self.streams_asked = True
        if seen.origin is None:
            out.append(enc.command_long_encode(seen.sysid, seen.compid, apm.MAV_CMD_REQUEST_MESSAGE, 0,
                                               apm.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN, 0, 0, 0, 0, 0, 0))
        if not any(p in seen.params for p in rules.param_asks):
            out += [enc.param_request_read_encode(seen.sysid, seen.compid, name.encode(), -1)
                    for name in rules.param_asks]
        return out
