"""Test-wide settings: hypothesis's profile. The tiers are declared in the test files themselves.

Tiers. ``make test`` (what CI runs) runs everything. ``make test-fast`` runs the pure cores, their properties and
the in-process protocol tests in simulated time, in under a minute: it leaves out the tests marked

- ``slow``: whole simulated missions (campaign runs, golden runs, end-to-end scenarios, baselines) and the fuzzer;
- ``interop``: real outside programs or real time: MAVProxy, MAVSDK, Chromium, Ray, vehicles served over UDP in
  real time, command-line subprocesses, sockets;
- ``firmware``: the ArduPilot SITL binary (every file with "firmware" in its name carries it).

A test file declares its tier with a module-level ``pytestmark`` under its imports; a single test of another tier
carries its own ``@pytest.mark.interop``. A file without either is fast. Nothing here names a test
(the layout tests check that).

Two at a time. ``make test`` runs the suite on two workers (pytest-xdist, ``--dist loadgroup``): the suite took
18.5 min on one core of the 2-core CI machine, against a budget of 15. Each test file is one group, kept on one
worker in its order (its module fixtures set up once). Every test that starts an outside program or keeps real
time (``firmware``, ``interop``) is in one group, ``outside``: they run one after another as before, beside the
in-process tests on the other worker, so two SITLs, two Ray clusters or two real-time servers never compete for the
two cores and the wall-clock guards keep the margins they were set with. Tests marked ``exclusive`` need the
machine to themselves (the README walkthrough uses the default ports 5760 and 14550, which any served vehicle
sends to; MAVSDK's flight-mode read-back, which fails beside a busy worker: its file says so): ``make test`` runs
them afterwards, alone.

In CI (CI=true) hypothesis explores a fixed pseudo-random set of cases, so a submission's result is reproducible;
on a developer's machine every run explores new ones.
"""

from __future__ import annotations

import os

import pytest
from hypothesis import settings

# no wall-clock deadline per example (tests never assert on wall-clock time: on a busy 2-core machine an example
# of the clearance property took 257 ms against hypothesis's default 200 ms and failed a correct test)
settings.register_profile("dev", deadline=None)
settings.register_profile("ci", derandomize=True, database=None, deadline=None)
settings.load_profile("ci" if os.environ.get("CI") else "dev")


OUTSIDE = "outside"  # the group of tests that start outside programs or keep real time


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Each test's xdist group (see the module docstring): its file's, or ``outside``."""
    for item in items:
        if item.get_closest_marker("xdist_group"):
            continue
        outside = item.get_closest_marker("firmware") or item.get_closest_marker("interop")
        item.add_marker(pytest.mark.xdist_group(OUTSIDE if outside else item.nodeid.split("::")[0]))
