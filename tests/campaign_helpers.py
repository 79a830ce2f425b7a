"""Helpers of the campaign tests: a short scenario with a link loss, spec files, and trial functions that
misbehave on purpose (a worker that dies once, a trial that ignores the alarm), importable by Ray workers as
``tests.campaign_helpers``."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

from sim.campaign.trial import Trial, inputs_row

TUNNEL = (Path(__file__).resolve().parent.parent / "sim" / "scenarios" / "tunnel.toml").read_text()


def jam_scenario(tmp: Path, name: str = "jam", duration: float = 14.0) -> Path:
    """The tunnel, cut short, with the link jammed from 3 s to 8 s: a loss, a return and a regain in 14 s."""
    text = TUNNEL.replace('name = "tunnel"', f'name = "{name}"').replace("duration = 200.0",
                                                                          f"duration = {duration}")
    text += '\n[[events]]\nt = 3.0\naction = "jam"\nduration = 5.0\n'
    path = tmp / f"{name}.toml"
    path.write_text(text)
    return path


def write_spec(tmp: Path, body: str) -> Path:
    path = tmp / "spec.toml"
    path.write_text(body)
    return path


def quick_row(trial: Trial, **metrics) -> dict:
    """A finished row without simulating: for tests of what happens around trials."""
    return {**inputs_row(trial), "status": "ok", "error": None, "passed": True, **metrics}


def dies_once(trial: Trial) -> dict:
    """Kills its worker process the first time (a marker file named by the scenario text records it), then
    returns a row: the retry of a dead worker's trial made visible."""
    marker = Path(trial.source).with_suffix(f".died-{trial.seed}")
    if not marker.exists():
        marker.write_text("died\n")
        os._exit(17)
    return quick_row(trial)


def ignores_alarm(trial: Trial) -> dict:
    """Blocks SIGALRM and sleeps: only the driver's hard limit can end it."""
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGALRM})
    while True:
        time.sleep(0.2)


def sleeps(trial: Trial) -> dict:
    """Sleeps far past any test's timeout, in a way the alarm can interrupt."""
    time.sleep(60)
    return quick_row(trial)


def pid_row(trial: Trial) -> dict:
    """A quick row carrying the worker's process id, in ``error`` (a free text column)."""
    return {**quick_row(trial), "error": str(os.getpid())}
