"""Constants of the bytes on the wire that both ends need and no generated module names.

The MAVLink 2 frame layout (what ``link.codec`` reads a datagram by and ``link.signing`` finds a signature by),
the HEARTBEAT's protocol version, and the value the lease messages send for "no lease". Everything the dialect
defines (message ids, MAV_CMD, MAV_FRAME, MAV_RESULT ...) comes from the generated module instead.
"""

from __future__ import annotations

STX_V2 = 0xFD  # the first byte of a MAVLink 2 frame
HEADER_V2 = 10  # bytes before the payload
CHECKSUM = 2  # CRC-16 after the payload
SIGNATURE_BLOCK = 13  # link id (1) + timestamp (6) + signature (6), after the checksum of a signed frame
IFLAG_SIGNED = 0x01  # incompatibility flag: the frame carries a signature block

MAVLINK_VERSION = 3  # HEARTBEAT.mavlink_version (what pymavlink's heartbeat_send fills in)
NO_INDEX = 0xFFFF  # LEASE_EVENT / LEASE_STATUS: no lease (no owner, nothing expired)
