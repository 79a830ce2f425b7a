"""The timeline of a run of a real autopilot, as a native run has one of its leases: what the autopilot did over
time (its mode timeline against the radio link and the distance driven back). A companion run's return is its
return-service lease, which drives in GUIDED: that is what its timeline counts as the return. Its trajectory is
every run's (``sim.report.trajectory``).

``run`` is a ``sim.runner.Run`` of an autopilot's plant: it has the plant (``run.plant``: its rows, its link, the
times it heard its station), the world and the scenario. A run of PX4 (``sim.plants.px4``) has the same record;
its plant names its modes (``mode_names``, ``return_modes``, ``autopilot``), which default to ArduPilot's."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sim.firmware.lockstep import MODE_NAMES
from sim.firmware.operator import RETURN_MODES
from sim.plots import plt, save
from vehicle.lease import Holder


def _columns(run) -> dict[str, np.ndarray]:
    rows = run.plant.rows
    a = np.array([r[:10] for r in rows], dtype=float) if rows else np.zeros((0, 10))
    return {"t": a[:, 0], "x": a[:, 1], "y": a[:, 2], "ex": a[:, 3], "ey": a[:, 4], "mode": a[:, 5],
            "link": a[:, 6], "rssi": a[:, 7]}


def _returning(run, modes: np.ndarray) -> np.ndarray:
    """Per tick, whether a return was under way: the companion's return-service lease in a run's trace, else a
    firmware failsafe mode (the companion drives its return in GUIDED, the mode the operator drives in)."""
    trace = getattr(run, "trace", None)
    if run.plant.leases and trace is not None:
        return np.array(trace.holder, dtype=int) == int(Holder.RETURN_SERVICE)
    return np.isin(modes, tuple(getattr(run.plant, "return_modes", RETURN_MODES)))


def timeline(run, path: Path) -> Path:
    c = _columns(run)
    t = c["t"]
    fig, axes = plt.subplots(3, 1, figsize=(11, 7), sharex=True, gridspec_kw={"height_ratios": [1.4, 1, 1]})
    ax = axes[0]
    tap = run.plant.link.tap
    names = getattr(run.plant, "mode_names", MODE_NAMES)
    autopilot = getattr(run.plant, "autopilot", "ArduPilot")
    seen = sorted({int(k) for k in c["mode"]} | {int(k) for _t, k in tap.modes})
    levels = {k: i for i, k in enumerate(seen)}
    ax.step(t, [levels[int(k)] for k in c["mode"]], where="post", color="tab:purple")
    ax.set_yticks(range(len(seen)), [names.get(k, str(k)) for k in seen], fontsize=8)
    for e in (run.metrics or {}).get("firmware_modes", []):
        ax.axvline(e["t"], color="0.8", lw=0.6)
        ax.annotate(e["mode"], (e["t"], 0.98), xycoords=("data", "axes fraction"), fontsize=6, rotation=90,
                    va="top", ha="right")
    ax.set_ylabel("firmware mode")
    ax = axes[1]
    ax.plot(t, c["link"], color="tab:green", lw=0.8, label="packet delivery (radio)")
    heard = np.zeros_like(t)
    if len(t) and run.plant.heard:
        k = np.clip(np.round(np.array(run.plant.heard) / (t[1] - t[0] if len(t) > 1 else 1)).astype(int) - 1, 0,
                    len(t) - 1)
        heard[k] = 1.0
    hearer = "the companion" if run.plant.leases else "the firmware"
    ax.vlines(t[heard > 0], 0, 0.15, color="tab:green", lw=0.5, alpha=0.6, label=f"station heard by {hearer}")
    ax.set_ylim(-0.05, 1.05)
    ax.set_ylabel("link")
    ax2 = ax.twinx()
    ax2.plot(t, c["rssi"], color="tab:red", lw=0.6, alpha=0.7)
    ax2.set_ylabel("RSSI (dBm)", color="tab:red")
    ax.legend(loc="lower left", fontsize=7)
    ax = axes[2]
    step = np.concatenate([[0.0], np.hypot(np.diff(c["x"]), np.diff(c["y"]))]) if len(t) else np.zeros(0)
    returning = _returning(run, c["mode"])
    ax.plot(t, np.cumsum(step * returning), color="tab:blue")
    ax.set_ylabel("driven back (m)")
    ax.set_xlabel("simulated time since the firmware was ready (s)")
    version = tap.version if autopilot != "ArduPilot" else f"ArduPilot {tap.version}"  # PX4's says "PX4 v..."
    fig.suptitle(f"{run.scenario.name} ({version}, seed {run.seed}, policy {run.policy})")
    return save(fig, path)

