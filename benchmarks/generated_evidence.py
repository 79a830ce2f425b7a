"""The generated worlds' "Done when" tables (issue 30) from finished sweeps of ``sim/campaign/specs/generated.toml``
and ``generated_firmware.toml`` (run into the same directory): per family and policy, how many trials lost the
link, how many of those the return itself brought back, the P95 time to link pooled over both robots and for each,
the mean rest distance from the loss, and wall contacts while a return held the robot.

    python benchmarks/generated_evidence.py OUT_DIR [--seeds FIRST-LAST]

``--seeds`` keeps the trials of those seeds only (the held-out ones, say).

Figures only, read from ``trials.parquet``; the last lines say, per family, whether returnlink's pooled P95 is at
most each baseline's (the issue's target), and nothing is asserted. The P95 is the campaign summary's
(``sim.campaign.store.percentile``: a trial's own value, no interpolation).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from link.storage import StoredFileError
from sim.campaign.store import FINISHED, percentile, read_rows, rest_from_loss, time_to_link

POLICIES = ("returnlink", "backup", "smartrtl", "ardupilot-smartrtl")
ROBOTS = ("rover", "legged")


def _p95(rows: list[dict]) -> float:
    p = percentile([x for r in rows if (x := time_to_link(r)) is not None], 95)
    return float("nan") if p is None else p


def family_table(rows: list[dict], family: str) -> tuple[str, dict[str, float]]:
    """The README table of one family, and each policy's pooled P95."""
    lines = ["| policy | trials | pass | lost the link | regained by the return | P95 time to link, s (both / rover / "
             "legged) | mean rest from the loss | contacts in returns |", "|---|---|---|---|---|---|---|---|"]
    pooled: dict[str, float] = {}
    for pol in POLICIES:
        rs = [r for r in rows if r["scenario"] == family and r["policy"] == pol]
        if rs:
            pooled[pol] = _p95([r for r in rs if r.get("status") in FINISHED])
            lines.append(_policy_line(pol, rs, pooled[pol]))
    return "\n".join(lines), pooled


def _policy_line(pol: str, rs: list[dict], pooled: float) -> str:
    """One policy's line of a family's table, from its trials ``rs`` and its pooled P95."""
    ran = [r for r in rs if r.get("status") in FINISHED]
    lost = [r for r in ran if r.get("link_lost_s") is not None]
    by_return = sum(1 for r in lost if r.get("regained_by") == "return")
    passed = sum(1 for r in ran if r.get("passed"))
    rest = [x for r in lost if (x := rest_from_loss(r)) is not None]
    contacts = sum(int(r.get("collisions_during_return") or 0) for r in ran)
    errors = len(rs) - len(ran)
    return (f"| {pol} | {len(rs)}{f' ({errors} errors)' if errors else ''} | "
            f"{100 * passed / max(1, len(ran)):.0f} % | {len(lost)}/{len(ran)} | {by_return}/{len(lost)} | "
            f"{_p95_cell(ran, pooled)} | {float(np.mean(rest)) if rest else float('nan'):.2f} m | {contacts} |")


def _p95_cell(ran: list[dict], pooled: float) -> str:
    """The P95 cell: pooled, then each robot's when both flew; else pooled with the one robot named."""
    robots = [v for v in ROBOTS if any(r["vehicle"] == v for r in ran)]
    if len(robots) > 1:
        return " / ".join([f"{pooled:.2f}"] + [f"{_p95([r for r in ran if r['vehicle'] == v]):.2f}" for v in robots])
    kinds = sorted({r["vehicle"] for r in ran})
    return f"{pooled:.2f} ({', '.join(kinds)})"


def _seeds(text: str) -> range | None:
    first, _, last = text.partition("-")
    if not (first.isdigit() and last.isdigit()) or int(first) > int(last):
        return None
    return range(int(first), int(last) + 1)


def main(argv: list[str]) -> int:
    seeds = None
    if len(argv) == 3 and argv[1] == "--seeds":
        seeds = _seeds(argv[2])
        if seeds is None:
            print(f"generated_evidence: --seeds wants FIRST-LAST, e.g. 221-260, got {argv[2]!r}", file=sys.stderr)
            return 2
    elif len(argv) != 1:
        print(__doc__, file=sys.stderr)
        return 2
    try:
        rows = read_rows(Path(argv[0]) / "trials.parquet")
    except StoredFileError as e:
        print(f"generated_evidence: {e}", file=sys.stderr)
        return 2
    if seeds is not None:
        rows = [r for r in rows if r.get("seed") in seeds]
    errors = sum(1 for r in rows if r.get("status") == "error")
    told = f" (seeds {seeds.start}-{seeds.stop - 1})" if seeds is not None else ""
    print(f"## {argv[0]}{told}: {len(rows)} trials, {errors} errors")
    verdicts = []
    for family in sorted({r["scenario"] for r in rows}):
        table, pooled = family_table(rows, family)
        print(f"\n`{family}`\n\n{table}")
        rl = pooled.get("returnlink", float("nan"))
        for base in ("backup", "smartrtl"):
            if base in pooled:
                ok = rl <= pooled[base] + 1e-9
                verdicts.append(f"{family}: returnlink P95 {rl:.2f} s vs {base} {pooled[base]:.2f} s: "
                                f"{'at most' if ok else 'ABOVE'}")
    print("\n" + "\n".join(verdicts))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
