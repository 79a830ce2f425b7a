"""The firmware and PX4 for tests: CI sets RETURNLINK_ARDUROVER, so the firmware tests always run there and a missing or
broken binary fails them; on a machine with no firmware at all (no variable, nothing on PATH) they skip, saying so."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from sim.firmware.locate import ENV, FirmwareNotFound, find_firmware


def firmware_or_skip() -> Path:
    try:
        return find_firmware()
    except FirmwareNotFound as e:
        if os.environ.get(ENV):
            pytest.fail(f"{ENV} is set but unusable: {e}")
        pytest.skip(f"no ArduPilot Rover SITL on this machine ({e})")


SHARED_PX4 = Path(__file__).resolve().parents[2] / "shared" / "px4"  # the PX4 tree shared beside this checkout


def px4_or_skip() -> Path:
    """The PX4 to test: $RETURNLINK_PX4 (which must work if set), else the shared tree (which must work if there);
    with neither the test skips, saying so."""
    from sim.px4.locate import ENV as PX4_ENV
    from sim.px4.locate import PX4NotFound, check_px4_dir, find_px4

    if os.environ.get(PX4_ENV):
        try:
            return find_px4()
        except PX4NotFound as e:
            pytest.fail(f"{PX4_ENV} is set but unusable: {e}")
    if not SHARED_PX4.exists():
        pytest.skip(f"no PX4: {PX4_ENV} is unset and {SHARED_PX4} is absent")
    return check_px4_dir(SHARED_PX4)


def short_scenario(tmp_path: Path, name: str = "tunnel", duration: float = 100.0) -> Path:
    """A built-in scenario cut to ``duration`` simulated s, as a file (trials hash the scenario's text)."""
    import sim

    text = (Path(sim.__file__).parent / "scenarios" / f"{name}.toml").read_text()
    lines = [f"duration = {duration}" if line.startswith("duration =") else line for line in text.splitlines()]
    path = tmp_path / f"{name}-short.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


def group_gone(pgid: int) -> bool:
    """Whether no process of group ``pgid`` is left (the PX4 a test started, stopped by its own process group)."""
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return True
    return False
