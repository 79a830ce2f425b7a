"""The two pictures every run leaves behind: where the robot went, and what the leases did over time.

The trajectory is drawn in the true frame (ground truth): paths, where the link was lost and regained, where each
return started and ended, its displacement circle and its target as the place the robot truly laid that crumb.
The vehicle's own view, the estimated path, trail and planned route with its target, is drawn too and labelled
"estimate frame", since that is where the vehicle chose them.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from sim.lease_record import BlockRecord
from sim.plots import draw_trail, draw_world, plt, save
from sim.scenario import Scenario
from sim.world import World

STATE_NAMES = ("NO_OWNER", "TELEOP", "AWAITING_CLAIM", "RETURNING", "HOLDING", "NAVIGATING")


class Run(Protocol):
    """What the pictures read of a finished ``sim.runner.Run`` of a plant with leases; named here, not imported,
    because the plants that draw with this module are imported by the loop (docs/architecture.md §2: no circle)."""

    scenario: Scenario
    kind: str
    seed: int
    policy: str
    metrics: dict
    world: World
    trace: Any  # the per-tick record (``sim.runner.Trace``): true and estimated paths, holder, state, link
    vehicle: Any  # returnlink's vehicle: its trail
    blocks: list[BlockRecord]
    losses: list[tuple[float, float | None]]
    link_backs: list[tuple[float, float | None]]

    def true_at(self, t: float) -> tuple[float, float]: ...


def _draw_run(ax, run: Run) -> None:
    v, tr = run.vehicle, run.trace
    true, est = np.array(tr.true), np.array(tr.est)
    ax.plot(true[:, 1], true[:, 0], color="k", lw=0.9, alpha=0.55, label="true path (true frame)")
    ax.plot(est[:, 1], est[:, 0], color="tab:orange", lw=0.9, alpha=0.8, label="estimated path (estimate frame)")
    draw_trail(ax, v.trail.points(), v.trail.link_good(), " (estimate frame)")
    for b in run.blocks:
        if b.route is not None and len(b.route) >= 2:
            ax.plot(b.route[:, 1], b.route[:, 0], color="tab:blue", lw=2.2, alpha=0.8, zorder=6,
                    label="return route (estimate frame)")
        if b.target is not None:
            ax.plot(b.target[1], b.target[0], marker="*", ms=15, color="tab:blue", alpha=0.5, zorder=7,
                    label="return target (estimate frame)")
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
    for _t, heard in run.losses:
        if heard is not None:
            x, y = run.true_at(heard)
            ax.plot(y, x, marker="X", ms=12, color="tab:red", zorder=9, label="link lost (last heard, true)")
    for _t, since in run.link_backs:
        if since is not None:
            x, y = run.true_at(since)
            ax.plot(y, x, marker="P", ms=12, color="tab:green", zorder=9, label="link back (true)")


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


def trajectory(run: Run, path: Path) -> Path:
    """Walls, denied zones, true and estimated paths, crumbs by link tag, return routes, displacement circles,
    and where the link was lost and regained; with a close-up of the returns when they are small on the map."""
    fig, ax = plt.subplots(figsize=(11, 8))
    draw_world(ax, run.world, run.scenario.bounds)
    _draw_run(ax, run)
    m = run.metrics or {}
    ax.set_title(f"{run.scenario.name} ({run.kind}, seed {run.seed}, policy {run.policy}; true frame): "
                 f"{'PASSED' if m.get('passed') else 'FAILED'}, back {m.get('distance_back_m')} m")
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
        _draw_run(inset, run)
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
