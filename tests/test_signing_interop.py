"""Real clients against a keyed vehicle over loopback UDP (docs/architecture.md §4.1): MAVProxy with its signing module
flies it; MAVSDK 4, which cannot sign, can watch it (telemetry, parameter download) but not act on it."""

from __future__ import annotations

import time

import pytest
from mavsdk import ComponentType, Configuration, Mavsdk
from mavsdk.plugins.action import Action
from mavsdk.plugins.param import Param
from mavsdk.plugins.telemetry import Telemetry

from link.signing import Key, SigningVerdict
from tests.interop import MAVProxy, ServedVehicle, wait_until
from vehicle.app import State
from vehicle.keystore import write_key
from vehicle.params import SPECS

pytestmark = pytest.mark.interop

PASSPHRASE = "adit-7-returnlink"


@pytest.fixture()
def keyed(tmp_path):
    path = tmp_path / "v.key"
    write_key(path, Key.from_passphrase(PASSPHRASE))  # `returnlink keys new v.key --passphrase ...`
    served = ServedVehicle("tunnel", key_file=path)
    try:
        yield served
    finally:
        served.close()


def test_mavproxy_with_the_signing_module_flies_a_keyed_vehicle(keyed, tmp_path):
    served = keyed
    mp = MAVProxy(served.gcs_port, tmp_path, "param,mode,cmdlong,link,signing")
    say, log = mp.say, mp.log
    try:
        # unsigned, it can still download the parameters ...
        mp.wait_for_parameters(len(SPECS))
        say("param set LNK_TIMEOUT 5")  # ... but not set one
        wait_until(lambda: "unsigned PARAM_SET from 255 refused" in log.read_text(), 20, "the refusal")
        assert served.vehicle.params["LNK_TIMEOUT"] == 3.0
        say(f"signing key {PASSPHRASE}")
        wait_until(lambda: "Setup signing key" in log.read_text(), 20, "MAVProxy to take the key")
        say("param set LNK_TIMEOUT 5")
        wait_until(lambda: served.vehicle.params["LNK_TIMEOUT"] == 5.0, 20, "LNK_TIMEOUT = 5 on the vehicle")
        say("long 32100 1 0 10 0")  # MAV_CMD_REQUEST_OPERATOR_CONTROL: with a key, no one is granted the root
        wait_until(lambda: served.vehicle.book.owner == 255, 20, "MAVProxy to own the vehicle")
        say("mode RTL")
        wait_until(lambda: "DO_SET_MODE: ACCEPTED" in log.read_text(), 20, "DO_SET_MODE accepted")
        # the operator lease expired: the return plan ran (at the start of the adit there is no trail to follow)
        assert any(e.reason.name == "OPERATOR_EXPIRE" for e in served.vehicle.event_log)
        assert served.server.plant.endpoint.counters.signing[SigningVerdict.ACCEPT] > 0
    finally:
        mp.close()


def test_mavsdk_can_watch_a_keyed_vehicle_but_not_act(keyed):
    served = keyed
    sdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    try:
        sdk.add_any_connection(f"udpin://127.0.0.1:{served.gcs_port}")
        system = sdk.first_autopilot(10.0)
        assert system is not None, "MAVSDK did not discover the keyed vehicle"
        tel = Telemetry(system)
        wait_until(tel.health_all_ok, 20, "health_all_ok")
        assert abs(tel.position().latitude_deg - 47.3977) < 0.001
        par = Param(system)
        assert par.get_param_float("LNK_TIMEOUT") == pytest.approx(3.0)
        assert len(par.get_all_params().float_params) == len(SPECS)
        with pytest.raises(Exception):  # noqa: B017 - MAVSDK's own ParamError: no answer to an unsigned set
            par.set_param_float("LNK_TIMEOUT", 4.5)
        with pytest.raises(Exception):  # noqa: B017 - MAVSDK's own ActionError: no answer to an unsigned command
            Action(system).return_to_launch()
        time.sleep(0.3)
        assert served.vehicle.params["LNK_TIMEOUT"] == 3.0
        assert served.vehicle.book.owner is None and served.vehicle.state() == State.NO_OWNER
        assert served.server.plant.endpoint.counters.signing[SigningVerdict.UNSIGNED] > 0
    finally:
        sdk.destroy()
