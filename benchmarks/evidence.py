"""Writes the tables of docs/evidence.md from the sweeps they came from, so no figure there is typed by hand.

    python benchmarks/evidence.py NAME=OUT_DIR [NAME=OUT_DIR ...] [--doc docs/evidence.md] [--tree HASH]

Each table in the page sits between two markers; the first says how to write it and from which sweep:

    <!-- evidence: table=compare sweep=companion spec=sim/campaign/specs/companion.toml rows=tunnel,culvert -->
    ...the table and a line saying where it came from...
    <!-- /evidence -->

``sweep`` names a sweep; ``NAME=OUT_DIR`` on the command line says where that sweep's output is (the directory
``returnlink sim sweep SPEC --out OUT_DIR`` wrote, read from its ``trials.parquet``). Every section whose sweeps
were given is written again, the others are left exactly as they are, so re-running this after a sweep refreshes
that sweep's tables. ``--tree`` is the commit the sweep ran on (default: this checkout's HEAD); it is written into
the marker and the line under the table with the spec, so each table says what it is evidence of.

Tables (``table=``), each over finished trials (``ok`` and ``failed``; errors are counted apart); time to link is
from the loss to the link regained, "never" when that trial's link never came back; P95 is the 95th-percentile
trial's own value (``sim.campaign.store.percentile``, as in every sweep table):

- ``family``: one generated family (``family=``, optional ``seeds=FIRST-LAST``): per policy, trials, pass rate, how
  many lost the link and how many of those the return brought back, P95 time to link pooled and per robot, mean
  rest from the loss, contacts in returns (``benchmarks/generated_evidence.py``'s table).
- ``builtin``: per scenario (``rows=``), P95 time to link of returnlink / backup / smartrtl for the rover and the
  legged robot, and returnlink's against SmartRTL's mean rest from the loss; ``weak=SWEEP`` adds a row per scenario
  of that sweep (its station's power in the name) with returnlink's loss cycles per run in place of the rest.
- ``seek``: per robot and policy (``split=POLICY,...``: those policies get a row per swept parameter value, the
  others are read at the first value, where the parameter changes nothing of theirs), time to link p50 / p90 / P95,
  mean rest from the loss, contacts in returns.
- ``compare``: per scenario (``rows=``) and policy (``policies=``, in that order, on whichever robot flew it), pass
  rate, trials regained by the return, time to link p50 / P95, mean rest from the loss, contacts in returns.
- ``drive``: per scenario (``rows=``) and policy (``policies=``), on whichever robot flew it: trials, contacts in
  returns, collisions in all (the operator's drive included), link losses per trial (mean), time to link P95 and its
  ratio to the first policy's on the same scenario (issue 41: is the comparison of the returns, not of the drivers).
- ``spread``: time to link under a one-tick perturbation (issue 38). The sweep swept one parameter (``param=``,
  default LNK_TIMEOUT) over two values one tick apart; each trial (scenario, robot, seed, policy) is paired with its
  twin and the gap between their times to link is the spread. Per robot: pairs, mean / P95 / largest gap, pairs more
  than 1 s apart; ``before=SWEEP`` (with ``before_tree=HASH``, kept as written) adds the same rows for that sweep.

Exit 0 when written, 2 on a bad argument, a sweep that cannot be read or a marker that cannot be followed (file,
line and what).
"""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

from link.storage import StoredFileError, write_atomic
from sim.campaign.store import FINISHED, percentile, read_rows, rest_from_loss, time_to_link

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "evidence.md"
BEGIN = re.compile(r"^<!-- evidence: (.*?) -->$")
END = "<!-- /evidence -->"
ROBOTS = ("rover", "legged")
BASELINES = ("returnlink", "backup", "smartrtl")
FAMILY_POLICIES = ("returnlink", "backup", "smartrtl", "ardupilot-smartrtl")


class EvidenceError(Exception):
    """A section that cannot be written: the message names the file, line and what is wrong."""


# ----- figures (pure) -----------------------------------------------------------------------------------------
def finished(rows: list[dict]) -> list[dict]:
    return [r for r in rows if r.get("status") in FINISHED]


def ttl_values(rows: list[dict]) -> list[float]:
    return [x for r in rows if (x := time_to_link(r)) is not None]


def p(values: list[float], q: float) -> float | None:
    return percentile(values, q)


def seconds(v: float | None, digits: int) -> str:
    """A time to link as the tables print it: "never" for a link that never came back, "-" for no trial."""
    if v is None:
        return "-"
    return "never" if math.isinf(v) else f"{v:.{digits}f}"


def with_unit(v: float | None, digits: int) -> str:
    """``seconds`` with its unit: "5.30 s", and "never" or "-" bare."""
    text = seconds(v, digits)
    return text if v is None or math.isinf(v) else f"{text} s"


def mean(values: list[float]) -> float | None:
    return float(np.mean(values)) if values else None


def rests(rows: list[dict]) -> list[float]:
    return [x for r in rows if r.get("link_lost_s") is not None and (x := rest_from_loss(r)) is not None]


def contacts(rows: list[dict]) -> int:
    return sum(int(r.get("collisions_during_return") or 0) for r in rows)


def params_of(row: dict) -> dict[str, float]:
    text = row.get("params") or ""
    return json.loads(text) if text else {}


def _pick(rows: list[dict], **want: str) -> list[dict]:
    return [r for r in rows if all(r.get(k) == v for k, v in want.items())]


# ----- the tables (pure: rows in, markdown out) ---------------------------------------------------------------
def family_table(rows: list[dict], family: str, seeds: range | None = None) -> str:
    """One generated family, as benchmarks/generated_evidence.py prints it."""
    if seeds is not None:
        rows = [r for r in rows if r.get("seed") in seeds]
    lines = ["| policy | trials | pass | lost the link | regained by the return | P95 time to link, s (both / rover / "
             "legged) | mean rest from the loss | contacts in returns |", "|---|---|---|---|---|---|---|---|"]
    for pol in FAMILY_POLICIES:
        rs = _pick(rows, scenario=family, policy=pol)
        if not rs:
            continue
        ran = finished(rs)
        lost = [r for r in ran if r.get("link_lost_s") is not None]
        by_return = sum(1 for r in lost if r.get("regained_by") == "return")
        passed = sum(1 for r in ran if r.get("passed"))
        robots = [v for v in ROBOTS if any(r["vehicle"] == v for r in ran)]
        both = seconds(p(ttl_values(ran), 95), 2)
        if len(robots) > 1:
            p95 = " / ".join([both] + [seconds(p(ttl_values(_pick(ran, vehicle=v)), 95), 2) for v in robots])
        else:
            p95 = f"{both} ({', '.join(sorted({r['vehicle'] for r in ran}))})"
        rest = mean(rests(ran))
        errors = len(rs) - len(ran)
        lines.append(f"| {pol} | {len(rs)}{f' ({errors} errors)' if errors else ''} | "
                     f"{100 * passed / max(1, len(ran)):.0f} % | {len(lost)}/{len(ran)} | {by_return}/{len(lost)} | "
                     f"{p95} | {'-' if rest is None else f'{rest:.2f} m'} | {contacts(ran)} |")
    return "\n".join(lines)


def _order(names: set[str], rows_opt: list[str] | None) -> list[str]:
    listed = [n for n in rows_opt or [] if n in names]
    return listed + sorted(names - set(listed))


def builtin_table(rows: list[dict], order: list[str] | None = None, weak: list[dict] | None = None) -> str:
    """Per scenario and robot, P95 time to link of returnlink / backup / smartrtl; rest from the loss of returnlink
    vs smartrtl (per robot); rows of a weak-radio sweep carry returnlink's loss cycles per run instead."""
    lines = ["| scenario | rover: returnlink / backup / smartrtl | legged: returnlink / backup / smartrtl | rest from "
             "loss, returnlink vs smartrtl (rover, legged) |", "|---|---|---|---|"]

    def p95s(rs: list[dict], robot: str) -> str:
        return " / ".join(seconds(p(ttl_values(_pick(rs, vehicle=robot, policy=pol)), 95), 2) for pol in BASELINES)

    ran = finished(rows)
    for sc in _order({r["scenario"] for r in ran}, order):
        rs = _pick(ran, scenario=sc)
        rest = []
        for robot in ROBOTS:
            mine, theirs = (mean(rests(_pick(rs, vehicle=robot, policy=pol))) for pol in ("returnlink", "smartrtl"))
            rest.append("-" if mine is None or theirs is None else f"{mine:.1f} vs {theirs:.1f} m")
        lines.append(f"| {sc} | {p95s(rs, 'rover')} | {p95s(rs, 'legged')} | {', '.join(rest)} |")
    for sc in _order({r["scenario"] for r in finished(weak or [])}, order):
        rs = _pick(finished(weak or []), scenario=sc)
        powers = sorted({params_of(r).get("radio.power_dbm") for r in rs} - {None})
        name = f"{sc}, {', '.join(f'{w:g}' for w in powers)} dBm" if powers else f"{sc}, weak radio"
        cycles = []
        for robot in ROBOTS:
            counts = [int(r.get("link_cycles") or 0) for r in _pick(rs, vehicle=robot, policy="returnlink")]
            cycles.append(f"{np.mean(counts):.2f} (max {max(counts)})" if counts else "-")
        lines.append(f"| {name} | {p95s(rs, 'rover')} | {p95s(rs, 'legged')} | loss cycles {' / '.join(cycles)} |")
    return "\n".join(lines)


def _label(pol: str, params: dict[str, float]) -> str:
    return ", ".join([pol] + [f"{k} {v:g}" for k, v in sorted(params.items()) if not k.startswith("radio.")])


def seek_table(rows: list[dict], split: list[str]) -> str:
    """Per robot and policy (``split`` policies once per swept value), time to link p50 / p90 / P95, mean rest from
    the loss, contacts in returns."""
    lines = ["| robot | policy | time to link | rest from loss (mean) | contacts in returns |", "|---|---|---|---|---|"]
    ran = finished(rows)
    values = sorted({json.dumps(params_of(r), sort_keys=True) for r in ran})
    for robot in [v for v in ROBOTS if _pick(ran, vehicle=v)]:
        for pol in _order({r["policy"] for r in ran}, list(BASELINES)):
            for value in values if pol in split else values[:1]:
                rs = [r for r in _pick(ran, vehicle=robot, policy=pol)
                      if json.dumps(params_of(r), sort_keys=True) == value]
                if not rs:
                    continue
                ttl = ttl_values(rs)
                *lower, top = (p(ttl, q) for q in (50, 90, 95))
                times = " / ".join([*(seconds(v, 1) for v in lower), with_unit(top, 1)])
                rest = mean(rests(rs))
                label = _label(pol, json.loads(value)) if pol in split else pol
                lines.append(f"| {robot} | {label} | {times} | {'-' if rest is None else f'{rest:.1f} m'} | "
                             f"{contacts(rs)} |")
    return "\n".join(lines)


def _two_times(ttl: list[float]) -> str:
    a, b = p(ttl, 50), p(ttl, 95)
    if a is not None and b is not None and not math.isinf(a) and not math.isinf(b):
        return f"{a:.1f} / {b:.1f} s"
    return " / ".join("never" if v is not None and math.isinf(v) else (f"{v:.1f} s" if v is not None else "-")
                      for v in (a, b))


def compare_table(rows: list[dict], order: list[str] | None, policies: list[str]) -> str:
    """Per scenario and policy (on whichever robot flew it): pass rate, regained by the return, time to link p50 /
    P95, mean rest from the loss, contacts in returns."""
    lines = ["| scenario | robot | policy | pass rate | by return | time to link p50 / p95 | rest from loss (mean) | "
             "contacts in returns |", "|---|---|---|---|---|---|---|---|"]
    ran = finished(rows)
    for sc in _order({r["scenario"] for r in ran}, order):
        for pol in _order({r["policy"] for r in _pick(ran, scenario=sc)}, policies):
            for robot in sorted({r["vehicle"] for r in _pick(ran, scenario=sc, policy=pol)}):
                rs = _pick(ran, scenario=sc, policy=pol, vehicle=robot)
                rate = sum(1 for r in rs if r.get("passed")) / len(rs)
                back = sum(1 for r in rs if r.get("regained_by") == "return")
                rest = mean(rests(rs))
                lines.append(f"| {sc} | {robot} | {pol} | {rate:.1f} | {back}/{len(rs)} | {_two_times(ttl_values(rs))} "
                             f"| {'-' if rest is None else f'{rest:.1f} m'} | {contacts(rs)} |")
    return "\n".join(lines)


def drive_table(rows: list[dict], order: list[str] | None, policies: list[str]) -> str:
    """Per scenario and policy: the drive's figures beside the return's (``drive`` in the module docstring)."""
    lines = ["| scenario | robot | policy | trials | contacts in returns | collisions in all | link losses per trial | "
             "P95 time to link | P95 against the first |", "|---|---|---|---|---|---|---|---|---|"]
    ran = finished(rows)
    for sc in _order({r["scenario"] for r in ran}, order):
        first: float | None = None
        for pol in _order({r["policy"] for r in _pick(ran, scenario=sc)}, policies):
            rs = _pick(ran, scenario=sc, policy=pol)
            p95 = p(ttl_values(rs), 95)
            first = p95 if first is None else first
            ratio = "-" if p95 is None or not first or math.isinf(p95) or math.isinf(first) else f"{p95 / first:.2f}x"
            losses = mean([float(r.get("link_cycles") or 0) for r in rs])
            robots = ", ".join(sorted({r["vehicle"] for r in rs}))
            lines.append(f"| {sc} | {robots} | {pol} | {len(rs)} | {contacts(rs)} | "
                         f"{sum(int(r.get('collisions') or 0) for r in rs)} | {losses:.2f} | "
                         f"{with_unit(p95, 2)} | {ratio} |")
    return "\n".join(lines)


def perturbation_gaps(rows: list[dict], param: str) -> dict[str, list[float]]:
    """Per robot, the gap in time to link between each trial and its twin one parameter value away (both finished,
    both regained; a trial whose twin never regained is a gap of inf)."""
    pairs: dict[tuple, dict[float, float]] = {}
    for r in finished(rows):
        ttl, value = time_to_link(r), params_of(r).get(param)
        if ttl is None or value is None:
            continue
        pairs.setdefault((r["scenario"], r["vehicle"], r["seed"], r["policy"]), {})[value] = ttl
    gaps: dict[str, list[float]] = {}
    for (_, robot, _, _), twins in sorted(pairs.items()):
        if len(twins) == 2:
            a, b = twins.values()
            gaps.setdefault(robot, []).append(math.inf if math.isinf(a) != math.isinf(b) else
                                              0.0 if math.isinf(a) else abs(a - b))
    return gaps


def spread_table(rows: list[dict], param: str, before: list[dict] | None = None,
                 trees: tuple[str, str] = ("", "")) -> str:
    """Per tree and robot: the one-tick spread of time to link (``perturbation_gaps``)."""
    lines = ["| tree | robot | pairs | mean gap | P95 gap | largest gap | pairs over 1 s apart |",
             "|---|---|---|---|---|---|---|"]
    for label, rs in ((trees[0], before), (trees[1], rows)):
        if rs is None:
            continue
        for robot, gaps in sorted(perturbation_gaps(rs, param).items()):
            shown = [with_unit(v, 2) for v in (mean(gaps), p(gaps, 95), max(gaps))]
            lines.append(f"| {label} | {robot} | {len(gaps)} | {' | '.join(shown)} | "
                         f"{sum(1 for g in gaps if g > 1.0)} |")
    return "\n".join(lines)


# ----- the page (pure: text and sweeps in, text out) ----------------------------------------------------------
def parse_marker(text: str) -> dict[str, str]:
    out = {}
    for word in text.split():
        key, eq, value = word.partition("=")
        if not eq or not value:
            raise ValueError(f"{word!r} is not KEY=VALUE")
        out[key] = value
    return out


def _list(opts: dict[str, str], key: str) -> list[str] | None:
    return opts[key].split(",") if key in opts else None


def _seeds(text: str) -> range:
    first, _, last = text.partition("-")
    if not (first.isdigit() and last.isdigit()) or int(first) > int(last):
        raise ValueError(f"seeds wants FIRST-LAST, e.g. 221-260, got {text!r}")
    return range(int(first), int(last) + 1)


def table_for(opts: dict[str, str], sweeps: Callable[[str], list[dict]]) -> str:
    kind = opts.get("table")
    rows = sweeps(opts["sweep"])
    if kind == "family":
        return family_table(rows, opts["family"], _seeds(opts["seeds"]) if "seeds" in opts else None)
    if kind == "builtin":
        return builtin_table(rows, _list(opts, "rows"), sweeps(opts["weak"]) if "weak" in opts else None)
    if kind == "seek":
        return seek_table(rows, _list(opts, "split") or [])
    if kind == "compare":
        return compare_table(rows, _list(opts, "rows"), _list(opts, "policies") or list(BASELINES))
    if kind == "drive":
        return drive_table(rows, _list(opts, "rows"), _list(opts, "policies") or list(BASELINES))
    if kind == "spread":
        before = sweeps(opts["before"]) if "before" in opts else None
        return spread_table(rows, opts.get("param", "LNK_TIMEOUT"), before,
                            (f"`{opts.get('before_tree', '?')}` (before)", f"`{opts.get('tree', '?')}`"))
    raise ValueError(f"table={kind!r}: family, builtin, seek, compare, drive or spread")


def provenance(opts: dict[str, str], counts: Callable[[str], tuple[int, int]]) -> str:
    """The line under a table: the spec and tree its sweep ran, and how many trials it holds."""
    parts = []
    for key in ("sweep", "weak", "before"):
        if key in opts:
            n, errors = counts(opts[key])
            note = {"weak": " (weak radio)", "before": " (before)"}.get(key, "")
            parts.append(f"{n:,} trials, {errors} errors{note}")
    spec = ", ".join(f"`{s}`" for s in opts.get("spec", "?").split(","))
    seeds = f", seeds {opts['seeds']}" if "seeds" in opts else ""
    return (f"*Written by `benchmarks/evidence.py` from the sweep of {spec}{seeds} on tree `{opts.get('tree', '?')}` "
            f"({'; '.join(parts)}).*")


def rewrite(text: str, sweeps: dict[str, list[dict]], tree: str, doc: str = "docs/evidence.md") -> tuple[str, int]:
    """``text`` with every section whose sweeps are all in ``sweeps`` written from them; the number written."""
    lines = text.splitlines()
    out: list[str] = []
    written = 0
    k = 0
    while k < len(lines):
        line = lines[k]
        m = BEGIN.match(line)
        if m is None:
            out.append(line)
            k += 1
            continue
        try:
            opts = parse_marker(m.group(1))
            needed = [opts[key] for key in ("sweep", "weak", "before") if key in opts]
            if not needed:
                raise ValueError("no sweep=NAME")
        except ValueError as e:
            raise EvidenceError(f"{doc}:{k + 1}: {e}") from None
        end = next((j for j in range(k + 1, len(lines)) if lines[j] == END), None)
        if end is None:
            raise EvidenceError(f"{doc}:{k + 1}: no {END} after this marker")
        if not all(name in sweeps for name in needed):
            out += lines[k:end + 1]
            k = end + 1
            continue
        opts["tree"] = tree
        try:
            table = table_for(opts, lambda name: sweeps[name])
        except (KeyError, ValueError) as e:
            raise EvidenceError(f"{doc}:{k + 1}: {e}") from None

        def counts(name: str) -> tuple[int, int]:
            return len(sweeps[name]), sum(1 for r in sweeps[name] if r.get("status") == "error")

        marker = " ".join(f"{key}={value}" for key, value in opts.items())
        out += [f"<!-- evidence: {marker} -->", "", table, "", provenance(opts, counts), "", END]
        written += 1
        k = end + 1
    return "\n".join(out) + "\n", written


# ----- the shell ----------------------------------------------------------------------------------------------
def _head() -> str:
    done = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True)
    return done.stdout.strip() or "unknown"


def main(argv: list[str]) -> int:
    doc, tree, given = DOC, None, {}
    args = list(argv)
    while args:
        a = args.pop(0)
        if a in ("--doc", "--tree") and args:
            doc, tree = (Path(args.pop(0)), tree) if a == "--doc" else (doc, args.pop(0))
        elif "=" in a and not a.startswith("-"):
            name, _, where = a.partition("=")
            given[name] = Path(where)
        else:
            print(__doc__, file=sys.stderr)
            return 2
    if not given:
        print(__doc__, file=sys.stderr)
        return 2
    try:
        sweeps = {name: read_rows(where / "trials.parquet") for name, where in given.items()}
        text = doc.read_text(encoding="utf-8")
        new, written = rewrite(text, sweeps, tree or _head(), str(doc))
    except (StoredFileError, EvidenceError, OSError) as e:
        print(f"evidence: {e}", file=sys.stderr)
        return 2
    if written == 0:
        print(f"evidence: no section of {doc} reads only the sweeps given ({', '.join(given)})", file=sys.stderr)
        return 2
    write_atomic(doc, new)
    print(f"evidence: wrote {written} table(s) of {doc} from {', '.join(f'{k}={v}' for k, v in given.items())}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
