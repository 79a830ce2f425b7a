"""The pictures a run leaves behind: where the robot went (one trajectory plot for every plant, and for a served
run), and what the leases did over time (a run of returnlink's vehicle; an autopilot's modes over time are
``sim.firmware.report.timeline``).

The trajectory is drawn in the true frame (ground truth): the true path (coloured by the autopilot's mode where one
flew, marked where a return drove), the estimated path, where the link was lost and regained, where each return
started and ended, its displacement circle and its target as the place the robot truly laid that crumb. The
vehicle's own view, its trail and planned route with its target, is drawn too and labelled "estimate frame", since
that is where the vehicle chose them (moved into the true frame by the vehicle's origin, ``frame_offset``: a
companion's is its autopilot's start).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from sim.lease_record import BlockRecord
from sim.plots import draw_trail, draw_world, plt, save
from sim.scenario import Scenario
from sim.world import World
from vehicle.lease import Holder

STATE_NAMES = ("NO_OWNER", "TELEOP", "AWAITING_CLAIM", "RETURNING", "HOLDING", "NAVIGATING")
MODE_COLOURS = {"GUIDED": "tab:green", "HOLD": "tab:orange", "RTL": "tab:red", "SMART_RTL": "tab:blue",
                "MANUAL": "0.5",
                # PX4's nav states (``sim.plants.px4``): Offboard is its GUIDED, AUTO_LOITER its Hold
                "OFFBOARD": "tab:green", "AUTO_LOITER": "tab:orange", "AUTO_RTL": "tab:red"}


class Run(Protocol):
    """What the pictures read of a finished ``sim.runner.Run``, or of a ``sim.serve.Server`` (no metrics, no
    trace, no blocks: its ``path``); named here, not imported, because the plants that draw with this module are
    imported by the loops (docs/architecture.md §2: no circle)."""

    scenario: Scenario
    kind: str
    seed: int
    policy: str
    metrics: dict | None
    world: World
    plant: Any  # its ``rows`` (an autopilot's own record, with its modes), ``frame_offset``, the modes' meaning
    trace: Any  # the per-tick record of returnlink's leases (``sim.runner.Trace``), or None
    vehicle: Any  # returnlink's vehicle (its trail), or None
    blocks: list[BlockRecord]
    losses: list[tuple[float, float | None]]
    link_backs: list[tuple[float, float | None]]

    def true_at(self, t: float) -> tuple[float, float]: ...


@dataclass(frozen=True)
class Track:
    """A run's paths as arrays of (north, east), true and estimated (the estimate in the true frame), the
    autopilot's mode at each point where one flew, and whether a return was under way there."""

    true: np.ndarray
    est: np.ndarray
    modes: np.ndarray | None
    returning: np.ndarray | None


def track(run: Run) -> Track:
    """The trace of returnlink's leases where they flew (its return: the return service's lease), else the
    autopilot's own rows (its return: a return mode), else a served run's path."""
    rows = run.plant.rows
    modes = np.array([r[5] for r in rows], dtype=int) if rows else None
    trace = run.trace
    if trace is not None and trace.rows:
        true, est = np.array(trace.true, dtype=float), np.array(trace.est, dtype=float)
        returning = np.array(trace.holder, dtype=int) == int(Holder.RETURN_SERVICE)
    elif rows:
        a = np.array([r[1:5] for r in rows], dtype=float)
        true, est = a[:, :2], a[:, 2:]
        returning = np.isin(modes, tuple(run.plant.return_modes))
    else:
        p = np.array(getattr(run, "path", ()), dtype=float).reshape(-1, 4)
        true, est, returning = p[:, :2], p[:, 2:], None
    return Track(true, est, modes, returning)


def _draw_paths(ax, run: Run, tr: Track) -> None:
    """The estimated path, the true path (by mode where an autopilot flew), and the stretches driven by a return."""
    ax.plot(tr.est[:, 1], tr.est[:, 0], color="tab:orange", lw=0.9, alpha=0.8, label="estimated path")
    if tr.modes is None:
        ax.plot(tr.true[:, 1], tr.true[:, 0], color="k", lw=0.9, alpha=0.55, label="true path (true frame)")
    else:
        names = run.plant.mode_names
        for k in np.unique(tr.modes):
            name = names.get(int(k), str(k))
            sel = np.where(tr.modes == k, 1.0, np.nan)
            ax.plot(tr.true[:, 1] * sel, tr.true[:, 0] * sel, color=MODE_COLOURS.get(name, "k"), lw=1.6,
                    label=f"true path, {name}")
    if tr.returning is not None and tr.returning.any():
        sel = np.where(tr.returning, 1.0, np.nan)
        ax.plot(tr.true[:, 1] * sel, tr.true[:, 0] * sel, color="tab:blue", lw=3.2, alpha=0.35,
                label="true path during a return")


def _draw_blocks(ax, run: Run, offset: np.ndarray) -> None:
    """Each return block: its route and target as the vehicle planned them (estimate frame), its target where the
    robot truly laid that crumb, its displacement circle around where it truly started, where it ended."""
    for b in run.blocks:
        if b.route is not None and len(b.route) >= 2:
            route = np.asarray(b.route) + offset
            ax.plot(route[:, 1], route[:, 0], color="tab:blue", lw=2.2, alpha=0.8, zorder=6,
                    label="return route (estimate frame)")
        if b.target is not None:
            ax.plot(b.target[1] + offset[1], b.target[0] + offset[0], marker="*", ms=15, color="tab:blue", alpha=0.5,
                    zorder=7, label="return target (estimate frame)")
        if b.target_true is not None:
            ax.plot(b.target_true[1], b.target_true[0], marker="*", ms=15, color="tab:cyan", mec="k", zorder=7,
                    label="return target (true, where its crumb was laid)")
        if math.isfinite(b.max_disp_allowed) and b.max_disp_allowed < 5000:
            a = np.linspace(0, 2 * math.pi, 400)
            ax.plot(b.start[1] + b.max_disp_allowed * np.sin(a), b.start[0] + b.max_disp_allowed * np.cos(a),
                    ls="--", color="tab:blue", lw=0.8, label="max displacement (around the true start)")
        if b.end is not None:
            ax.plot(b.end[1], b.end[0], marker="s", ms=7, color="tab:blue", mfc="white", zorder=8,
                    label="return ended (true)")


def _draw_link(ax, run: Run) -> None:
    """Where the link was lost (last heard) and came back, from the run's lease record; for a run without one, the
    loss and the place of rest its metrics name."""
    for _t, heard in run.losses:
        if heard is not None:
            x, y = run.true_at(heard)
            ax.plot(y, x, marker="X", ms=12, color="tab:red", zorder=9, label="link lost (last heard, true)")
    for _t, since in run.link_backs:
        if since is not None:
            x, y = run.true_at(since)
            ax.plot(y, x, marker="P", ms=12, color="tab:green", zorder=9, label="link back (true)")
    m = run.metrics or {}
    if not run.losses and m.get("loss_position"):
        p = m["loss_position"]
        ax.plot(p[1], p[0], marker="X", ms=12, color="tab:red", zorder=9, label="link lost (last heard, true)")
    if not run.blocks and m.get("rest_position"):
        p = m["rest_position"]
        ax.plot(p[1], p[0], marker="s", ms=12, color="tab:blue", mfc="white", zorder=9,
                label="at rest after the return (true)")


def _draw_run(ax, run: Run, tr: Track) -> None:
    offset = np.array(run.plant.frame_offset, dtype=float)
    _draw_paths(ax, run, tr)
    if run.vehicle is not None:
        crumbs = run.vehicle.crumbs()  # the trail as the vehicle's port gives it
        draw_trail(ax, crumbs.points + offset, crumbs.link_good, " (estimate frame)")
    _draw_blocks(ax, run, offset)
    _draw_link(ax, run)


def _return_box(run: Run, margin: float = 3.0) -> tuple[float, float, float, float] | None:
    """North/east extent of the returns and the link events, for a close-up."""
    pts = []
    for b in run.blocks:
        pts += [b.start] + ([b.end] if b.end else []) + ([b.target] if b.target else [])
        pts += [b.target_true] if b.target_true else []
        if b.route is not None:
            pts += [tuple(p) for p in b.route]
    pts += [run.true_at(h) for _t, h in run.losses if h is not None]
    if not pts:
        return None
    a = np.array(pts)
    return (a[:, 0].min() - margin, a[:, 1].min() - margin, a[:, 0].max() + margin, a[:, 1].max() + margin)


def _title(run: Run) -> str:
    m = run.metrics
    where = f"{run.scenario.name} ({run.kind}, seed {run.seed}, policy {run.policy}; true frame)"
    if m is None:  # served: nothing judged
        return f"{where}: served, {getattr(run, 't', 0.0):.0f} simulated s"
    return f"{where}: {'PASSED' if m.get('passed') else 'FAILED'}, back {m.get('distance_back_m')} m"


def trajectory(run: Run, path: Path) -> Path:
    """Walls, denied zones, true and estimated paths, crumbs by link tag, return routes, displacement circles,
    and where the link was lost and regained; with a close-up of the returns when they are small on the map."""
    tr = track(run)
    fig, ax = plt.subplots(figsize=(11, 8))
    draw_world(ax, run.world, run.scenario.bounds)
    _draw_run(ax, run, tr)
    ax.set_title(_title(run))
    handles, labels = ax.get_legend_handles_labels()
    uniq = dict(zip(labels, handles, strict=True))
    ax.legend(uniq.values(), uniq.keys(), loc="upper left", bbox_to_anchor=(1.04, 1.0), borderaxespad=0.0,
              fontsize=7)  # beside the map: inside, it hid the place where the link was lost
    box = _return_box(run)
    bounds = run.scenario.bounds
    if box is not None and max(box[2] - box[0], box[3] - box[1]) < 0.35 * max(bounds[2] - bounds[0],
                                                                             bounds[3] - bounds[1]):
        inset = ax.inset_axes((1.12, 0.0, 0.55, 0.55))
        draw_world(inset, run.world)
        _draw_run(inset, run, tr)
        side = max(box[2] - box[0], box[3] - box[1]) / 2
        cn, ce = (box[0] + box[2]) / 2, (box[1] + box[3]) / 2
        inset.set_xlim(ce - side, ce + side)
        inset.set_ylim(cn - side, cn + side)
        inset.set_title("close-up of the return", fontsize=9)
        ax.indicate_inset_zoom(inset, edgecolor="0.4")
    return save(fig, path)


def timeline(run: Run, path: Path) -> Path:
    """Lease index, holder and state; link up/down; RSSI; distance back over time."""
    tr = run.trace
    t = np.array(tr.t)
    fig, axes = plt.subplots(4, 1, figsize=(11, 8.5), sharex=True,
                             gridspec_kw={"height_ratios": [1.3, 1.3, 1, 1]})
    ax = axes[0]
    idx = np.array(tr.index, dtype=float)
    holder = np.array(tr.holder)
    ax.step(t, idx, where="post", color="0.3", lw=1)
    for h, colour, name in ((1, "tab:green", "operator"), (2, "tab:blue", "return service")):
        sel = holder == h
        ax.scatter(t[sel], idx[sel], s=3, color=colour, label=f"holder: {name}")
    for e in run.vehicle.event_log:
        ax.axvline(e.t, color="0.7", lw=0.6)
        ax.annotate(e.reason.name, (e.t, 0.98), xycoords=("data", "axes fraction"), fontsize=6, rotation=90,
                    va="top", ha="right")
    ax.set_ylabel("lease index")
    ax.legend(loc="upper left", fontsize=7)
    ax = axes[1]
    ax.step(t, tr.state, where="post", color="tab:purple")
    ax.set_yticks(range(len(STATE_NAMES)), STATE_NAMES, fontsize=7)
    ax.set_ylabel("state")
    ax = axes[2]
    ax.plot(t, tr.link, color="tab:green", lw=0.8, label="packet delivery (radio)")
    ax.fill_between(t, 0, np.array(tr.heard, dtype=float), color="tab:green", alpha=0.15, step="post",
                    label="owner heard, link good (vehicle)")
    ax.set_ylim(-0.05, 1.05)
    ax.set_ylabel("link")
    ax2 = ax.twinx()
    ax2.plot(t, tr.rssi, color="tab:red", lw=0.6, alpha=0.7)
    ax2.set_ylabel("RSSI (dBm)", color="tab:red")
    ax.legend(loc="lower left", fontsize=7)
    ax = axes[3]
    true = np.array(tr.true)
    step = np.concatenate([[0.0], np.hypot(*np.diff(true, axis=0).T)]) if len(true) else np.zeros(0)
    back = np.cumsum(step * (np.array(tr.holder) == 2))
    ax.plot(t, back, color="tab:blue")
    ax.set_ylabel("distance back (m)")
    ax.set_xlabel("simulated time (s)")
    fig.suptitle(f"{run.scenario.name} ({run.kind}, seed {run.seed}, policy {run.policy})")
    return save(fig, path)
