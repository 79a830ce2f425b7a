"""Parameters: the contract table, range checks that keep the old value, and .parm round trips."""

from __future__ import annotations

import math

import pytest

from vehicle import params
from vehicle.params import ParamError, Params


def test_defaults_file_matches_the_contract():
    on_disk = params.parse_parm(params.DEFAULTS_FILE.read_text(), "returnlink.parm")
    assert on_disk == {s.name: float(s.default) for s in params.SPECS}
    assert all(len(s.name) <= 16 for s in params.SPECS)
    assert params.load_defaults()["LNK_TIMEOUT"] == 3.0


@pytest.mark.parametrize("name, value", [("LNK_TIMEOUT", 0.1), ("LNK_TIMEOUT", 121), ("RTL_TARGET", 1.5),
                                         ("TRL_MAX_PTS", 10), ("RTL_SPEED", math.nan), ("NO_SUCH", 1)])
def test_refused_sets_keep_the_old_value(name, value):
    p = Params()
    before = dict(p.values)
    with pytest.raises(ParamError) as e:
        p.set(name, value)
    assert name in str(e.value)
    assert p.values == before


def test_parm_round_trip_and_errors():
    p = Params()
    p.set("RTL_MAX_DISP", 75)
    text = params.format_parm(p.values)
    assert params.parse_parm(text)["RTL_MAX_DISP"] == 75.0
    assert params.parse_parm("RTL_SPEED,1.5\n")["RTL_SPEED"] == 1.5  # comma form
    with pytest.raises(ParamError, match="x.parm:2"):
        params.parse_parm("LNK_TIMEOUT 3\nRTL_SPEED fast\n", "x.parm")


def test_every_feature_config_starts_from_the_parameter_table():
    """Each feature's Config takes its defaults from the table and maps the same parameters in from_params: a
    vehicle booted on the defaults runs exactly the configs a bare ``Config()`` describes."""
    from vehicle.lease import LeaseConfig
    from vehicle.link_watch import WatchConfig
    from vehicle.navigation import FollowerConfig
    from vehicle.trail import TrailConfig

    defaults = Params()
    for config in (LeaseConfig, WatchConfig, TrailConfig, FollowerConfig):
        assert config.from_params(defaults) == config(), config.__name__
    assert LeaseConfig().watch == WatchConfig()
    changed = Params({"LNK_TIMEOUT": 7.0, "TRL_TOL": 0.5, "RTL_ARRIVE_R": 2.0, "LEASE_STALE_TAKE": 0})
    assert LeaseConfig.from_params(changed).link_timeout == WatchConfig.from_params(changed).timeout == 7.0
    assert TrailConfig.from_params(changed).tolerance == 0.5
    assert FollowerConfig.from_params(changed).arrive_radius == 2.0
    assert LeaseConfig.from_params(changed).stale_take is False
