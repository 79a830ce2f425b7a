"""The link map's "Done when" tables (issue 21) from a finished sweep of ``sim/campaign/specs/linkmap.toml`` and,
optionally, of ``linkmap_weak.toml``: per scenario and robot, returnlink's P95 time to link against the back-up and
SmartRTL baselines, collisions during returns, and rest distance from the loss point against SmartRTL's; for the
weak radio, loss cycles per run and how often the return itself regained the link.

    python benchmarks/linkmap_evidence.py OUT_DIR [WEAK_OUT_DIR]

Figures only, read from ``trials.parquet``; nothing is asserted (the targets are printed beside them).
"""

from __future__ import annotations

import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

from link.storage import StoredFileError
from sim.campaign.store import percentile, read_rows, rest_from_loss, time_to_link
from sim.registry import DEFAULT_POLICY

REST_RATIO = 0.25  # returnlink's mean rest distance at most this share of SmartRTL's
WEAK_CYCLES_MEAN, WEAK_CYCLES_MAX, WEAK_REGAINED = 1.5, 3, 0.99


def _p95(values: list[float]) -> float:
    p = percentile(values, 95)
    return float("nan") if p is None else p


def _groups(rows: list[dict], pooled: bool) -> dict[tuple[str, str], dict[str, list[dict]]]:
    out: dict[tuple[str, str], dict[str, list[dict]]] = defaultdict(lambda: defaultdict(list))
    for r in rows:
        out[(r["scenario"], "both" if pooled else r["vehicle"])][r["policy"]].append(r)
    return out


def main_table(rows: list[dict], pooled: bool = False) -> tuple[str, int]:
    lines = ["| scenario | robot | n | P95 ttl returnlink | backup | smartrtl | P95 ok | collisions in returns "
             "(rl/bk/srtl) | rest m returnlink | smartrtl | ratio | rest ok |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    misses = 0
    for (sc, veh), by in sorted(_groups(rows, pooled).items()):
        p95 = {p: _p95([x for r in by.get(p, []) if (x := time_to_link(r)) is not None])
               for p in ("returnlink", "backup", "smartrtl")}
        coll = {p: sum(int(r.get("collisions_during_return") or 0) for r in by.get(p, []))
                for p in ("returnlink", "backup", "smartrtl")}
        rest = {p: [x for r in by.get(p, []) if (x := rest_from_loss(r)) is not None]
                for p in ("returnlink", "smartrtl")}
        rl_rest = float(np.mean(rest["returnlink"])) if rest["returnlink"] else float("nan")
        sr_rest = float(np.mean(rest["smartrtl"])) if rest["smartrtl"] else float("nan")
        ratio = rl_rest / sr_rest if sr_rest > 0 else float("nan")
        ok_t = p95["returnlink"] <= p95["backup"] + 1e-9 and p95["returnlink"] <= p95["smartrtl"] + 1e-9
        ok_r = ratio <= REST_RATIO
        misses += (not ok_t) + (not ok_r) + (coll["returnlink"] > 0)
        lines.append(f"| {sc} | {veh} | {len(by.get('returnlink', []))} | {p95['returnlink']:.2f} | "
                     f"{p95['backup']:.2f} | {p95['smartrtl']:.2f} | {'yes' if ok_t else 'NO'} | "
                     f"{coll['returnlink']}/{coll['backup']}/{coll['smartrtl']} | {rl_rest:.2f} | {sr_rest:.2f} | "
                     f"{ratio:.3f} | {'yes' if ok_r else 'NO'} |")
    return "\n".join(lines), misses


def weak_table(rows: list[dict]) -> tuple[str, int]:
    lines = ["| robot | policy | n | loss cycles mean | max | regained by the return | P95 ttl | errors |",
             "|---|---|---|---|---|---|---|---|"]
    misses = 0
    by: dict[tuple[str, str], list[dict]] = defaultdict(list)
    for r in rows:
        by[(r["vehicle"], r["policy"])].append(r)
    for (veh, pol), rs in sorted(by.items()):
        ran = [r for r in rs if r.get("status") in ("ok", "failed")]
        cycles = [int(r.get("link_cycles") or 0) for r in ran]
        lost = [r for r in ran if r.get("link_lost_s") is not None]
        by_return = sum(1 for r in lost if r.get("regained_by") == "return")
        share = by_return / len(lost) if lost else float("nan")
        mean = float(np.mean(cycles)) if cycles else float("nan")
        top = max(cycles) if cycles else 0
        if pol == DEFAULT_POLICY:  # the scenario's own plan: the one these thresholds judge
            misses += (mean > WEAK_CYCLES_MEAN) + (top > WEAK_CYCLES_MAX) + (share < WEAK_REGAINED)
        ttl = _p95([x for r in ran if (x := time_to_link(r)) is not None])
        lines.append(f"| {veh} | {pol} | {len(rs)} | {mean:.2f} | {top} | {by_return}/{len(lost)} ({share:.0%}) | "
                     f"{ttl:.2f} | {len(rs) - len(ran)} |")
    return "\n".join(lines), misses


def main(argv: list[str]) -> int:
    if not argv:
        print(__doc__, file=sys.stderr)
        return 2
    try:
        rows = read_rows(Path(argv[0]) / "trials.parquet")
        weak = read_rows(Path(argv[1]) / "trials.parquet") if len(argv) > 1 else None
    except StoredFileError as e:
        print(f"linkmap_evidence: {e}", file=sys.stderr)
        return 2
    errors = sum(1 for r in rows if r.get("status") == "error")
    table, misses = main_table(rows)
    print(f"## {argv[0]}: {len(rows)} trials, {errors} errors\n\n{table}\n")
    pooled, _ = main_table(rows, pooled=True)
    print(f"### both robots pooled\n\n{pooled}\n")
    if weak is not None:
        wt, wm = weak_table(weak)
        print(f"## {argv[1]}: {len(weak)} trials\n\n{wt}\n")
        misses += wm
    print(f"targets missed: {misses}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
