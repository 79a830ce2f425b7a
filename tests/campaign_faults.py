"""Trial functions that misbehave on purpose, importable by Ray workers (``tests.campaign_faults``), for the
campaign tests: a worker that dies once, a trial that ignores the alarm, a trial that is quick and fine."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

from sim.campaign.trial import Trial, inputs_row


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
