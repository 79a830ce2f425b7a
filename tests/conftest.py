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

In CI (CI=true) hypothesis explores a fixed pseudo-random set of cases, so a submission's result is reproducible;
on a developer's machine every run explores new ones.
"""

from __future__ import annotations

import os

from hypothesis import settings

# no wall-clock deadline per example (tests never assert on wall-clock time: on a busy 2-core machine an example
# of the clearance property took 257 ms against hypothesis's default 200 ms and failed a correct test)
settings.register_profile("dev", deadline=None)
settings.register_profile("ci", derandomize=True, database=None, deadline=None)
settings.load_profile("ci" if os.environ.get("CI") else "dev")
