"""The two pictures of a firmware run, like a native run's: where the rover went (true frame, coloured by the
firmware's mode, with the loss and rest points and the EKF's path) and what the firmware did over time (its mode
timeline against the radio link and the distance driven back). A companion run's return is its return-service
lease, which drives in GUIDED: that is what its pictures mark as the return.

``run`` is a ``sim.runner.Run`` of a firmware plant, or a ``sim serve`` server of one (``sim.serve.Server``): both
have the plant (``run.plant``: its rows, its link, the times it heard its station), the world and the scenario. A
run of PX4 (``sim.plants.px4``) has the same record; its plant names its modes (``mode_names``, ``return_modes``,
``autopilot``), which default to ArduPilot's."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sim.firmware.lockstep import MODE_NAMES
from sim.firmware.operator import RETURN_MODES
from sim.plots import draw_world, plt, save
from vehicle.lease import Holder

MODE_COLOURS = {"GUIDED": "tab:green", "HOLD": "tab:orange", "RTL": "tab:red", "SMART_RTL": "tab:blue",
                "MANUAL": "0.5",
                # PX4's nav states (``sim.plants.px4``): Offboard is its GUIDED, AUTO_LOITER its Hold
                "OFFBOARD": "tab:green", "AUTO_LOITER": "tab:orange", "AUTO_RTL": "tab:red"}


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


def trajectory(run, path: Path) -> Path:
    c = _columns(run)
    m = run.metrics or {}
    names = getattr(run.plant, "mode_names", MODE_NAMES)
    autopilot = getattr(run.plant, "autopilot", "ArduPilot")
    fig, ax = plt.subplots(figsize=(11, 8))
    draw_world(ax, run.world, run.scenario.bounds)
    estimator = "firmware EKF" if autopilot == "ArduPilot" else f"{autopilot} EKF2"
    ax.plot(c["ey"], c["ex"], color="0.55", lw=0.8, ls="--", label=f"{estimator} estimate (true frame via its origin)")
    modes = c["mode"].astype(int)
    for k in np.unique(modes):
        name = names.get(int(k), str(k))
        sel = np.where(modes == k, 1.0, np.nan)
        ax.plot(c["y"] * sel, c["x"] * sel, color=MODE_COLOURS.get(name, "k"), lw=1.6, label=f"true path, {name}")
    companion = run.plant.leases  # returnlink companion beside the firmware
    if companion:
        sel = np.where(_returning(run, modes), 1.0, np.nan)
        ax.plot(c["y"] * sel, c["x"] * sel, color="tab:blue", lw=3.2, alpha=0.6,
                label="true path under the companion's return lease")
    rest = "at rest after the return (true)" if companion else "at rest after the failsafe (true)"
    for key, marker, colour, label in (("loss_position", "X", "tab:red", "link lost (last heard, true)"),
                                       ("rest_position", "s", "tab:blue", rest)):
        p = m.get(key)
        if p:
            ax.plot(p[1], p[0], marker=marker, ms=12, color=colour, mfc="white" if marker == "s" else colour,
                    zorder=9, label=label)
    ax.set_title(f"{run.scenario.name} ({autopilot} firmware, seed {run.seed}, policy {run.policy}; true frame): "
                 f"{'PASSED' if m.get('passed') else 'FAILED'}, back {m.get('distance_back_m')} m")
    handles, labels = ax.get_legend_handles_labels()
    uniq = dict(zip(labels, handles, strict=True))
    ax.legend(uniq.values(), uniq.keys(), loc="upper left", bbox_to_anchor=(1.04, 1.0), borderaxespad=0.0,
              fontsize=7)  # beside the map: inside, it hid the place where the link was lost
    return save(fig, path)


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

