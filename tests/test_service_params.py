"""The parameter protocol alone: reads answered to anyone, writes only from the owner, every answer a PARAM_VALUE
(an unchanged one when a write is refused, with a STATUSTEXT saying why), accepted values saved."""

from __future__ import annotations

from tests.service_kit import OWNER, STRANGER, Kit, texts, types
from vehicle.params import SPECS, read_parm_file
from vehicle.services.base import mav
from vehicle.services.params import ParamServer


def param_set(name: str, value: float):
    return mav.MAVLink_param_set_message(1, 1, name.encode(), value, mav.MAV_PARAM_TYPE_REAL32)


def values(replies: list) -> list[tuple[str, float, int, int]]:
    return [(m.param_id, m.param_value, m.param_index, m.param_count) for m in replies
            if m.get_type() == "PARAM_VALUE"]


def test_the_list_is_every_parameter_in_table_order_as_real32():
    kit = Kit()
    replies = kit.send(ParamServer(kit.out, kit.vehicle), mav.MAVLink_param_request_list_message(1, 1),
                       sysid=STRANGER)
    assert [(n, i, c) for n, _, i, c in values(replies)] == [(s.name, i, len(SPECS)) for i, s in enumerate(SPECS)]
    assert {m.param_type for m in replies} == {mav.MAV_PARAM_TYPE_REAL32}


def test_a_read_by_name_or_index_answers_that_one_and_an_unknown_name_is_told():
    kit = Kit()
    params = ParamServer(kit.out, kit.vehicle)
    by_name = kit.send(params, mav.MAVLink_param_request_read_message(1, 1, b"LNK_TIMEOUT", -1))
    assert values(by_name) == [("LNK_TIMEOUT", kit.vehicle.params["LNK_TIMEOUT"], 0, len(SPECS))]
    assert values(kit.send(params, mav.MAVLink_param_request_read_message(1, 1, b"", 1)))[0][0] == SPECS[1].name
    assert kit.send(params, mav.MAVLink_param_request_read_message(1, 1, b"", len(SPECS))) == []
    assert texts(kit.send(params, mav.MAVLink_param_request_read_message(1, 1, b"NO_SUCH", -1))) == [
        "no parameter 'NO_SUCH'"]


def test_the_owner_sets_a_value_and_it_is_saved(tmp_path):
    kit = Kit()
    kit.take_control(OWNER)
    parm = tmp_path / "vehicle.parm"
    replies = kit.send(ParamServer(kit.out, kit.vehicle, parm), param_set("LNK_TIMEOUT", 5.0))
    assert values(replies) == [("LNK_TIMEOUT", 5.0, 0, len(SPECS))] and kit.vehicle.params["LNK_TIMEOUT"] == 5.0
    assert read_parm_file(parm)["LNK_TIMEOUT"] == 5.0


def test_a_stranger_gets_the_value_back_unchanged_and_why():
    kit = Kit()
    kit.take_control(OWNER)
    before = kit.vehicle.params["LNK_TIMEOUT"]
    replies = kit.send(ParamServer(kit.out, kit.vehicle), param_set("LNK_TIMEOUT", 9.0), sysid=STRANGER)
    assert types(replies) == ["STATUSTEXT", "PARAM_VALUE"] and values(replies)[0][1] == before
    assert texts(replies) == [f"param set from {STRANGER} refused: GCS {OWNER} is in control"]
    assert kit.vehicle.params["LNK_TIMEOUT"] == before and kit.vehicle.commands_rejected == 1


def test_a_value_out_of_range_is_refused_and_the_old_one_answered():
    kit = Kit()
    before = kit.vehicle.params["LNK_TIMEOUT"]
    replies = kit.send(ParamServer(kit.out, kit.vehicle), param_set("LNK_TIMEOUT", -4.0))
    assert values(replies)[0][1] == before and texts(replies)[0].startswith("param set refused: ")


def test_a_value_that_cannot_be_saved_is_in_use_and_said_so(tmp_path):
    kit = Kit()
    replies = kit.send(ParamServer(kit.out, kit.vehicle, tmp_path / "no such dir" / "v.parm"),
                       param_set("LNK_TIMEOUT", 6.0))
    assert kit.vehicle.params["LNK_TIMEOUT"] == 6.0 and values(replies)[0][1] == 6.0
    assert texts(replies)[0].startswith("param LNK_TIMEOUT set but not saved")


def test_a_set_of_an_unknown_name_is_refused_without_a_value():
    kit = Kit()
    assert texts(kit.send(ParamServer(kit.out, kit.vehicle), param_set("NO_SUCH", 1.0))) == [
        "param set refused: no parameter 'NO_SUCH'"]
