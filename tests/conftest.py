"""Test-wide settings. In CI (CI=true) hypothesis explores a fixed pseudo-random set of cases, so a submission's
result is reproducible; on a developer's machine every run explores new ones."""

from __future__ import annotations

import os

from hypothesis import settings

settings.register_profile("ci", derandomize=True, database=None)
if os.environ.get("CI"):
    settings.load_profile("ci")
