"""Link-loss policies a trial can fly (DESIGN §9): returnlink itself and the baselines it is compared against.

Every policy runs on the same vehicle and simulator, so only the policy differs between paired trials.
"""

from __future__ import annotations

POLICY_NAMES: tuple[str, ...] = ("returnlink", "hold", "rtl", "smartrtl", "backup")
DEFAULT_POLICY = "returnlink"


def check_policy(name: str) -> str:
    """The policy name, or ValueError listing the known ones."""
    if name not in POLICY_NAMES:
        raise ValueError(f"unknown policy {name!r}; known: {', '.join(POLICY_NAMES)}")
    return name
