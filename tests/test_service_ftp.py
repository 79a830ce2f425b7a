"""MAVLink FTP alone: every request gets NAK "unknown command" at once, an answer is never answered."""

from __future__ import annotations

from tests.service_kit import OWNER, Kit
from vehicle.services.base import mav
from vehicle.services.ftp import ERR_UNKNOWN_COMMAND, HEADER, OP_ACK, OP_NAK, PAYLOAD, FtpRefusal

OPEN_FILE_RO = 4  # an FTP request opcode (what MAVProxy opens its parameter file with)


def ftp(seq: int, opcode: int, session: int = 0) -> object:
    payload = HEADER.pack(seq, session, opcode, 0, 0, 0, 0, 0)
    return mav.MAVLink_file_transfer_protocol_message(0, 1, 1, list(payload + bytes(PAYLOAD - len(payload))))


def test_a_request_gets_a_nak_for_the_next_sequence_number():
    kit = Kit()
    [nak] = kit.send(FtpRefusal(kit.out), ftp(41, OPEN_FILE_RO, session=3))
    assert nak.get_type() == "FILE_TRANSFER_PROTOCOL" and (nak.target_system, nak.target_component) == (OWNER, 190)
    payload = bytes(nak.payload)
    seq, session, opcode, size, req_opcode = HEADER.unpack_from(payload)[:5]
    assert (seq, session, opcode, size, req_opcode) == (42, 3, OP_NAK, 1, OPEN_FILE_RO)
    assert payload[HEADER.size] == ERR_UNKNOWN_COMMAND


def test_an_answer_is_never_answered():
    kit = Kit()
    ftp_service = FtpRefusal(kit.out)
    assert kit.send(ftp_service, ftp(1, OP_ACK)) == [] and kit.send(ftp_service, ftp(1, OP_NAK)) == []
