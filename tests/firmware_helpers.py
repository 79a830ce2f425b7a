"""The firmware for tests: CI sets RETURNLINK_ARDUROVER, so the firmware tests always run there and a missing or
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


def short_scenario(tmp_path: Path, name: str = "tunnel", duration: float = 100.0) -> Path:
    """A built-in scenario cut to ``duration`` simulated s, as a file (trials hash the scenario's text)."""
    import sim

    text = (Path(sim.__file__).parent / "scenarios" / f"{name}.toml").read_text()
    lines = [f"duration = {duration}" if line.startswith("duration =") else line for line in text.splitlines()]
    path = tmp_path / f"{name}-short.toml"
    path.write_text("\n".join(lines) + "\n")
    return path
