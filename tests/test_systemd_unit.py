"""The systemd unit that starts the companion on boot (docs/architecture.md §11.1): restarted on failure, after the
serial devices, as a user in group dialout, and its ExecStart is a command line `returnlink companion` accepts."""

from __future__ import annotations

import configparser
import shlex
import sys
from pathlib import Path

import vehicle.companion
from sim.cli import build_parser
from vehicle.companion.links import parse_conn

if sys.version_info >= (3, 11):
    import tomllib
else:
    import tomli as tomllib

UNIT = Path(vehicle.companion.__file__).parent / "returnlink-companion.service"
STATE = "/var/lib/returnlink"


def _unit() -> configparser.ConfigParser:
    cp = configparser.ConfigParser(strict=False, interpolation=None, delimiters=("=",), comment_prefixes=("#", ";"))
    cp.optionxform = str  # systemd's keys are case-sensitive
    cp.read_string(UNIT.read_text(encoding="utf-8"), str(UNIT))
    return cp


def _argv() -> list[str]:
    return shlex.split(_unit()["Service"]["ExecStart"])


def test_the_unit_restarts_on_failure_after_the_serial_devices_as_a_dialout_user():
    u = _unit()
    service = u["Service"]
    assert service["Type"] == "simple"
    assert service["Restart"] == "on-failure"
    assert float(service["RestartSec"]) == 2
    assert service["User"] == "returnlink"
    assert "dialout" in service["SupplementaryGroups"].split()
    assert service["StateDirectory"] == "returnlink"
    for key in ("After", "Wants"):
        units = u["Unit"][key].split()
        assert "dev-ttyAMA0.device" in units and "dev-ttyUSB0.device" in units, (key, units)
        assert "network-online.target" in units
    assert u["Install"]["WantedBy"] == "multi-user.target"


def test_the_units_command_line_is_one_returnlink_companion_accepts():
    argv = _argv()
    assert argv[0] == "/opt/returnlink/bin/returnlink" and argv[1] == "companion"
    args = build_parser().parse_args(argv[1:])  # argparse's SystemExit (an unknown option, a bad value) fails
    assert args.command == "companion"
    assert args.autopilot == "serial:/dev/ttyAMA0:921600"
    assert args.gcs == ["serial:/dev/ttyUSB0:57600"]  # --gcs may be given again for another ground link
    for conn in [args.autopilot, *args.gcs]:
        assert parse_conn(conn).kind == "serial"
    assert args.params == f"{STATE}/companion.parm"  # in the StateDirectory, writable by the user
    assert not args.check and not args.configure  # it runs, not checks
    assert str(args.log) == f"{STATE}/logs"


def test_the_unit_ships_in_the_wheel():
    project = tomllib.loads((Path(__file__).resolve().parents[1] / "pyproject.toml").read_text(encoding="utf-8"))
    assert "*.service" in project["tool"]["setuptools"]["package-data"]["vehicle.companion"]
