"""Where a campaign's results live: ``DIR/trials.parquet`` (one row per trial) and ``DIR/summary.csv``.

The parquet file is the campaign's memory: it is rewritten atomically every few seconds while trials finish (less
often as it grows, so rewriting it never costs more than a twentieth of the time; see ``next_flush_gap``), so a
sweep stopped at any moment (Ctrl-C, a crash, a lost machine) resumes where it was by running it again into the
same DIR: trials with a row ``ok`` or ``failed`` are skipped, ``error`` rows are run again. A file that cannot be
read is reported and left alone, never replaced by an empty campaign.
"""

from __future__ import annotations

import csv
import io
import json
import math
import time
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from link.storage import StoredFileError, write_atomic
from sim.campaign.trial import Trial

TRIALS_FILE = "trials.parquet"
SUMMARY_FILE = "summary.csv"
FLUSH_EVERY_S = 5.0
FLUSH_SHARE = 20.0  # the gap between rewrites is at least this many times what the last rewrite cost

INPUTS = [("trial_id", pa.string()), ("scenario", pa.string()), ("source", pa.string()),
          ("scenario_text", pa.string()), ("vehicle", pa.string()), ("seed", pa.int64()),
          ("params", pa.string()), ("policy", pa.string())]
# every metric of docs/architecture.md §7 (scenario, vehicle, seed and policy are the inputs above); nested ones as JSON
# text
JSON_METRICS = ("lease_events", "failures", "loss_position", "rest_position", "blocks", "firmware_modes")
METRICS = [("sim_duration_s", pa.float64()), ("link_lost_s", pa.float64()), ("return_started_s", pa.float64()),
           ("reaction_latency_s", pa.float64()), ("link_regained_s", pa.float64()),
           ("distance_back_m", pa.float64()), ("max_displacement_m", pa.float64()),
           ("final_target_error_m", pa.float64()), ("collisions", pa.int64()),
           ("stale_commands_executed", pa.int64()), ("commands_rejected", pa.int64()),
           ("estimator_rmse_m", pa.float64()), ("trail_points", pa.int64()), ("trail_max_deviation_m", pa.float64()),
           ("real_time_factor", pa.float64()), ("lease_events", pa.string()), ("passed", pa.bool_()),
           ("failures", pa.string()), ("loss_position", pa.string()), ("rest_position", pa.string()),
           ("rest_link_quality", pa.float64()), ("link_cycles", pa.int64()), ("regained_by", pa.string()),
           ("collisions_during_return", pa.int64()), ("return_speed_mps", pa.float64()), ("blocks", pa.string()),
           ("relapses", pa.int64()),
           # vehicles ardurover and px4rover only (docs/architecture.md §10, §10.1): the autopilot's version and modes
           ("firmware", pa.string()), ("firmware_modes", pa.string())]
OUTCOME = [("status", pa.string()), ("error", pa.string()), ("cpu_s", pa.float64())]
SCHEMA = pa.schema(INPUTS + METRICS + OUTCOME)
FINISHED = ("ok", "failed")


def _cell(name: str, value):
    if value is None:
        return None
    if name in JSON_METRICS and not isinstance(value, str):
        return json.dumps(value, separators=(",", ":"))
    return value


def to_table(rows: Iterable[dict]) -> pa.Table:
    rows = list(rows)
    return pa.table({f.name: pa.array([_cell(f.name, r.get(f.name)) for r in rows], f.type) for f in SCHEMA},
                    schema=SCHEMA)


def read_rows(path: Path) -> list[dict]:
    """The rows of a trials file, or StoredFileError naming it when it is damaged or not a campaign's."""
    try:
        table = pq.read_table(path)
    except (OSError, pa.ArrowException) as e:
        raise StoredFileError(path, None, f"not a readable parquet file ({e}); move it away to start afresh") from None
    missing = [n for n, _ in INPUTS + [("status", None)] if n not in table.column_names]
    if missing:
        raise StoredFileError(path, None, f"not a campaign's trials file: no column {missing[0]!r}")
    return table.to_pylist()


def next_flush_gap(cost_s: float) -> float:
    """Seconds until the next rewrite of the trials file, after one that took ``cost_s``: every FLUSH_EVERY_S while
    the file is small, and FLUSH_SHARE times the rewrite's cost once it is large, so a campaign of 100,000 rows
    spends at most 1/FLUSH_SHARE of its driver's time rewriting (a fixed gap would make that quadratic); what a
    crash loses is at most one gap of finished trials, which a resume runs again."""
    return max(FLUSH_EVERY_S, FLUSH_SHARE * cost_s)


class Store:
    """The rows of one campaign directory, keyed by trial id, written back atomically."""

    def __init__(self, out: Path, clock=time.monotonic) -> None:
        self.out = Path(out)
        self.clock = clock
        self.path = self.out / TRIALS_FILE
        self.rows: dict[str, dict] = {}
        if self.path.exists():
            for r in read_rows(self.path):
                self.rows[r["trial_id"]] = r
        self._saved_at = clock()
        self._gap = FLUSH_EVERY_S

    def pending(self, trials: Iterable[Trial]) -> list[Trial]:
        """The trials still to run: never run, or whose last run ended in an error."""
        return [t for t in trials if self.rows.get(t.id, {}).get("status") not in FINISHED]

    def add(self, row: dict) -> None:
        self.rows[row["trial_id"]] = row
        if self.clock() - self._saved_at >= self._gap:
            self.flush()

    def flush(self) -> Path:
        began = self.clock()
        self.out.mkdir(parents=True, exist_ok=True)
        buf = io.BytesIO()
        pq.write_table(to_table(self.rows.values()), buf, compression="zstd")
        write_atomic(self.path, buf.getvalue())
        self._saved_at = self.clock()
        self._gap = next_flush_gap(self._saved_at - began)
        return self.path

    def write_summary(self) -> Path:
        rows = summary(self.rows.values())
        text = io.StringIO()
        w = csv.DictWriter(text, fieldnames=SUMMARY_COLUMNS, lineterminator="\n")
        w.writeheader()
        for r in rows:
            w.writerow({k: _fmt(v) for k, v in r.items()})
        path = self.out / SUMMARY_FILE
        write_atomic(path, text.getvalue())
        return path


# ----- the summary (pure) -------------------------------------------------------------------------------------
SUMMARY_COLUMNS = ["scenario", "vehicle", "policy", "params", "n", "ok", "failed", "errors", "pass_rate",
                   "link_regained_rate", "time_to_link_p50_s", "time_to_link_p90_s", "time_to_link_p99_s",
                   "distance_back_m_mean", "rest_from_loss_m_mean", "rest_from_loss_m_p90",
                   "collisions_during_return", "link_cycles_mean", "link_cycles_max", "relapses_mean", "relapses_max"]


def _json(v):
    return json.loads(v) if isinstance(v, str) else v


def time_to_link(row: dict) -> float | None:
    """Seconds from the link loss (owner last heard) to the link regained; inf when it never came back; None
    when the link was never lost or the trial did not run."""
    if row.get("status") not in FINISHED or row.get("link_lost_s") is None:
        return None
    back = row.get("link_regained_s")
    return math.inf if back is None else back - row["link_lost_s"]


def rest_from_loss(row: dict) -> float | None:
    """Metres between where the link was lost and where the first return chain came to rest (true frame)."""
    a, b = _json(row.get("loss_position")), _json(row.get("rest_position"))
    if row.get("status") not in FINISHED or not a or not b:
        return None
    return math.dist(a[:2], b[:2])


def percentile(values: list[float], q: float) -> float | None:
    """The empirical quantile (no interpolation: a trial's own value), so a share of never-regained trials shows
    as inf, not nan; every table of a sweep uses it (None for no values)."""
    return float(np.percentile(values, q, method="inverted_cdf")) if values else None


def _mean(values: list[float]) -> float | None:
    return float(np.mean(values)) if values else None


def summary(rows: Iterable[dict]) -> list[dict]:
    """One line per scenario x vehicle x policy x parameter values (a swept radio strength or LNK_TIMEOUT is
    a line of its own, not averaged away; ``params`` is "" when the spec swept none). Rates are over the trials
    that ran (errors are counted apart, they say nothing about the policy); time to link counts a never-regained
    link as infinite; link cycles are COMMS_LOST events per run."""
    return [_summary_line(key, rs) for key, rs in sorted(_groups(rows).items())]


def _groups(rows: Iterable[dict]) -> dict[tuple[str, str, str, str], list[dict]]:
    """The rows by scenario, vehicle, policy and parameter values ("" for none swept)."""
    groups: dict[tuple[str, str, str, str], list[dict]] = {}
    for r in rows:
        params = r.get("params") or ""
        groups.setdefault((r["scenario"], r["vehicle"], r["policy"], "" if params == "{}" else params), []).append(r)
    return groups


def _present(rows: list[dict], key: str) -> list:
    """The values of ``key`` in the rows that have one."""
    return [r[key] for r in rows if r.get(key) is not None]


def _rate(ran: list[dict], hits: int) -> float | None:
    return hits / len(ran) if ran else None


def _max(values: list) -> float | None:
    return max(values) if values else None


def _summary_line(key: tuple[str, str, str, str], rs: list[dict]) -> dict:
    """The summary of one group's trials (see ``summary``)."""
    scenario, vehicle, policy, params = key
    ran = [r for r in rs if r.get("status") in FINISHED]
    ttl = [x for r in ran if (x := time_to_link(r)) is not None]
    rest = [x for r in ran if (x := rest_from_loss(r)) is not None]
    coll = _present(ran, "collisions_during_return")
    cycles, relapsed = _present(ran, "link_cycles"), _present(ran, "relapses")
    return {
        "scenario": scenario, "vehicle": vehicle, "policy": policy, "params": params, "n": len(rs),
        "ok": sum(r["status"] == "ok" for r in rs), "failed": sum(r["status"] == "failed" for r in rs),
        "errors": sum(r["status"] == "error" for r in rs),
        "pass_rate": _rate(ran, sum(r["status"] == "ok" for r in ran)),
        "link_regained_rate": _rate(ran, sum(r.get("link_regained_s") is not None for r in ran)),
        "time_to_link_p50_s": percentile(ttl, 50), "time_to_link_p90_s": percentile(ttl, 90),
        "time_to_link_p99_s": percentile(ttl, 99),
        "distance_back_m_mean": _mean(_present(ran, "distance_back_m")),
        "rest_from_loss_m_mean": _mean(rest), "rest_from_loss_m_p90": percentile(rest, 90),
        "collisions_during_return": sum(coll) if coll else None,
        "link_cycles_mean": _mean(cycles), "link_cycles_max": _max(cycles),
        "relapses_mean": _mean(relapsed), "relapses_max": _max(relapsed),
    }


def _fmt(v) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return "inf" if math.isinf(v) else f"{v:.3f}".rstrip("0").rstrip(".")
    return str(v)


def format_table(rows: list[dict], columns: list[str] | None = None) -> str:
    """The summary as a markdown table (also readable on a terminal)."""
    columns = columns or SUMMARY_COLUMNS
    lines = ["| " + " | ".join(columns) + " |", "|" + "|".join("---" for _ in columns) + "|"]
    lines += ["| " + " | ".join(_fmt(r[c]) or "-" for c in columns) + " |" for r in rows]
    return "\n".join(lines)
