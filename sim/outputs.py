"""What every run leaves behind, whichever plant flew it: metrics.json, the operator's .tlog, the link map, the
trajectory and timeline plots, and the printed summary. The metrics are one pipeline (``sim.metrics.compute``); the
summary and the plots are the plant's (``Plant.summary``, ``Plant.pictures``): a firmware run has modes where a native
one has leases."""

from __future__ import annotations

from pathlib import Path

from link.linkmap_format import FILE_NAME
from sim import metrics


def compute(run) -> dict:
    return metrics.compute(run)


def summary(run, m: dict) -> str:
    return run.plant.summary(run, m)


def write_linkmap(run, path: Path) -> Path | None:
    """The vehicle's link map as ``linkmap.csv`` (``link.linkmap_format``), replaced atomically; None for a run
    whose vehicle keeps no map (the firmware's alone, or a companion that never booted). The map is in the vehicle's
    local frame as it knows it: for the native vehicle the true frame (its estimator starts at its true pose), for
    returnlink companion the autopilot's local frame, whose origin is the scenario's start (``run.frame_offset``
    in the true frame)."""
    linkmap = getattr(getattr(run, "vehicle", None), "linkmap", None)
    if linkmap is None:
        return None
    from link.linkmap_format import encode
    from link.storage import write_atomic

    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(path, encode(linkmap.cells()))
    return path


def write(run, out: Path, plots: bool = True) -> list[Path]:
    """metrics.json, run.tlog, linkmap.csv (a native or companion run) and (unless ``plots`` is off) trajectory.png and
    timeline.png in ``out``."""
    from sim.runner import write_metrics, write_tlog

    paths = [write_metrics(run.metrics, out / "metrics.json"), write_tlog(run, out / "run.tlog")]
    linkmap = write_linkmap(run, out / FILE_NAME)
    if linkmap is not None:
        paths.append(linkmap)
    if plots:
        paths += run.plant.pictures(run, out)
    return paths
