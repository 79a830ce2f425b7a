"""Test-wide settings: the tiers, and hypothesis's profile.

Tiers. ``make test`` (what CI runs) runs everything. ``make test-fast`` runs the pure cores, their properties and
the in-process protocol tests in simulated time, in under a minute: it leaves out the tests marked here

- ``slow``: whole simulated missions (campaign runs, golden runs, end-to-end scenarios, baselines) and the fuzzer;
- ``interop``: real outside programs or real time: MAVProxy, MAVSDK, Chromium, Ray, vehicles served over UDP in
  real time, command-line subprocesses, sockets;
- ``firmware``: the ArduPilot SITL binary.

A test file belongs to a tier by its name below (a new file is fast until listed); a few tests of an interop file
that need none of it are named one by one.

In CI (CI=true) hypothesis explores a fixed pseudo-random set of cases, so a submission's result is reproducible;
on a developer's machine every run explores new ones.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import settings

settings.register_profile("ci", derandomize=True, database=None)
if os.environ.get("CI"):
    settings.load_profile("ci")

SLOW = {"test_campaign.py", "test_campaign_radio.py", "test_reaction_latency.py", "test_e2e_link.py",
        "test_e2e_scenarios.py", "test_fuzz.py", "test_golden_runs.py", "test_policies.py", "test_linkmap_runs.py",
        "test_clearance_runs.py"}
INTEROP = {"test_campaign_ray.py", "test_cli.py", "test_companion_cli.py", "test_console.py",
           "test_interop_mavproxy.py", "test_interop_mavsdk.py", "test_interop_pymavlink.py", "test_map.py",
           "test_param_file.py", "test_proxy_serve.py", "test_signing_cli.py", "test_signing_interop.py",
           "test_transports.py"}
FIRMWARE_WORD = "firmware"  # test_firmware*.py: they start the real firmware
# tests of an interop file that run in-process in simulated time
FAST_IN_INTEROP = {"test_shell_keeps_the_link_through_a_10_s_idle", "test_one_shot_and_shell_share_one_command_table"}
# single interop tests in an otherwise fast file
INTEROP_TESTS = {"test_any_pymavlink_program_can_use_the_dialect_by_name", "test_mavsdk_mavlink_direct_loads_the_xml",
                 "test_strangers_cycling_source_ports_do_not_starve_the_owners_downlink",
                 "test_mavproxy_with_its_default_modules_gets_parameters_without_an_ftp_time_out"}


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        name = Path(str(item.fspath)).name
        test = item.originalname or item.name
        if FIRMWARE_WORD in name:
            item.add_marker(pytest.mark.firmware)
        if name in SLOW:
            item.add_marker(pytest.mark.slow)
        if (name in INTEROP and test not in FAST_IN_INTEROP) or test in INTEROP_TESTS:
            item.add_marker(pytest.mark.interop)
