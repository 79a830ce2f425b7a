"""``DIR/report.md``: what a campaign found, for a person: the pass-rate table, CDFs per policy of the time until
the link came back and of distances, and the worst trials with the command that replays each one.

Only the driver draws (matplotlib, Agg); workers never import this module.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from link.storage import write_atomic
from sim.campaign.store import FINISHED, format_table, rest_from_loss, summary, time_to_link
from sim.plots import plt, save

WORST = 10
TABLE_COLUMNS = ["scenario", "vehicle", "policy", "params", "n", "errors", "pass_rate", "link_regained_rate",
                 "time_to_link_p50_s", "time_to_link_p90_s", "rest_from_loss_m_mean", "collisions_during_return",
                 "link_cycles_mean", "link_cycles_max", "relapses_mean"]


def _cdf(ax, values: list[float], n: int, label: str) -> None:
    """Empirical CDF over all ``n`` trials: values that are inf (never happened) keep the curve below 1."""
    finite = np.sort([v for v in values if math.isfinite(v)])
    if n == 0:
        return
    y = np.arange(1, len(finite) + 1) / n
    ax.step(np.concatenate([[0.0], finite]), np.concatenate([[0.0], y]), where="post", label=f"{label} (n={n})")


def _legend(ax) -> None:
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="lower right", fontsize=8)
    else:
        ax.text(0.5, 0.5, "no trial has this metric", ha="center", transform=ax.transAxes, color="0.4")


def _per_policy(rows: list[dict], value) -> dict[str, tuple[list[float], int]]:
    out: dict[str, tuple[list[float], int]] = {}
    for r in rows:
        v = value(r)
        if v is None:
            continue
        vals, n = out.get(r["policy"], ([], 0))
        vals.append(v)
        out[r["policy"]] = (vals, n + 1)
    return out


def _cdf_panel(ax, rows: list[dict], value, xlabel: str, ylabel: str) -> None:
    """One CDF per policy of ``value(row)`` on ``ax``, labelled."""
    for policy, (vals, n) in sorted(_per_policy(rows, value).items()):
        _cdf(ax, vals, n, policy)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_ylim(0, 1.02)
    ax.grid(alpha=0.3)
    _legend(ax)


def plot_time_to_link(rows: list[dict], path: Path) -> Path:
    fig, ax = plt.subplots(figsize=(8, 5))
    _cdf_panel(ax, rows, time_to_link, "time from link loss to link regained (s)", "fraction of trials with a loss")
    ax.set_title("Time to link, per policy (a curve that stays below 1: links that never came back)")
    return save(fig, path)


def plot_distances(rows: list[dict], path: Path) -> Path:
    fig, axes = plt.subplots(1, 2, figsize=(12, 5))
    panels = ((lambda r: r.get("distance_back_m") if r.get("status") in FINISHED else None,
               "distance driven on return (m)"),
              (rest_from_loss, "distance from the loss point at rest (m)"))
    for ax, (value, label) in zip(axes, panels, strict=True):
        _cdf_panel(ax, rows, value, label, "fraction of trials")
    fig.suptitle("Distances, per policy")
    return save(fig, path)


def _badness(r: dict) -> tuple:
    """Errors first, then failures, then the longest time to link, then the farthest rest from the loss."""
    ttl = time_to_link(r)
    rest = rest_from_loss(r)
    return ({"error": 0, "failed": 1}.get(r["status"], 2), -(ttl if ttl is not None else -1.0),
            -(rest if rest is not None else -1.0), r["trial_id"])


def worst(rows: list[dict], k: int = WORST) -> list[dict]:
    return sorted(rows, key=_badness)[:k]


def write(out: Path, rows: Iterable[dict]) -> Path:
    rows = list(rows)
    ttl_png = plot_time_to_link(rows, out / "time_to_link_cdf.png")
    dist_png = plot_distances(rows, out / "distance_cdf.png")
    counts = {s: sum(r["status"] == s for r in rows) for s in ("ok", "failed", "error")}
    lines = [
        f"# Campaign report: {len(rows)} trials",
        "",
        f"{counts['ok']} ok (criteria met), {counts['failed']} failed (ran, criteria not met), "
        f"{counts['error']} error (raised or timed out). Rates below are over the trials that ran.",
        "",
        "## Pass rate per scenario, robot and policy",
        "",
        format_table(summary(rows), TABLE_COLUMNS),
        "",
        "The full table, with p99 and distances driven, is `summary.csv`; one row per trial is `trials.parquet`.",
        "",
        "## Time to link",
        "",
        f"![time to link]({ttl_png.name})",
        "",
        "## Distances",
        "",
        f"![distances]({dist_png.name})",
        "",
        "## Worst trials",
        "",
        "| trial | scenario | vehicle | seed | policy | params | status | time to link (s) | why | replay |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in worst(rows):
        ttl = time_to_link(r)
        why = r.get("error") or ("; ".join(_failures(r)) if r["status"] == "failed" else "")
        lines.append(
            f"| {r['trial_id']} | {r['scenario']} | {r['vehicle']} | {r['seed']} | {r['policy']} | {r['params']} | "
            f"{r['status']} | {'-' if ttl is None else ('never' if math.isinf(ttl) else f'{ttl:.1f}')} | "
            f"{why.replace('|', '/')} | `returnlink sim run --replay {out} {r['trial_id']}` |")
    path = out / "report.md"
    write_atomic(path, "\n".join(lines) + "\n")
    return path


def _failures(r: dict) -> list[str]:
    import json

    f = r.get("failures")
    return json.loads(f) if isinstance(f, str) else list(f or [])
