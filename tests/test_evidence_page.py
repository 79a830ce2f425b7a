"""docs/evidence.md's tables are written by benchmarks/evidence.py from sweep outputs, never by hand: every table of
the page lies in a marked section, every marked section can be followed, and the script writes a section from a
sweep's trials.parquet (its P95 the campaign summary's, "never" for a link that never came back), leaves the sections
of other sweeps alone, and names the file and line of a marker it cannot follow (exit 2)."""

from __future__ import annotations

import importlib.util
import json
import re
from pathlib import Path

import pyarrow.parquet as pq

from sim.campaign.store import percentile, to_table

ROOT = Path(__file__).resolve().parent.parent
PAGE = ROOT / "docs" / "evidence.md"
_PATH = ROOT / "benchmarks" / "evidence.py"


def _module():
    spec = importlib.util.spec_from_file_location("evidence", _PATH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _row(seed: int, vehicle: str, policy: str, ttl: float | None, contacts: int = 0, **params) -> dict:
    return {"trial_id": f"{vehicle}-{policy}-{seed}-{json.dumps(params)}", "scenario": "tunnel", "source": "tunnel",
            "scenario_text": "", "vehicle": vehicle, "seed": seed, "params": json.dumps(params, sort_keys=True),
            "policy": policy, "status": "ok", "passed": ttl is not None, "link_lost_s": 10.0,
            "link_regained_s": None if ttl is None else 10.0 + ttl,
            "regained_by": None if ttl is None else "return", "loss_position": [0.0, 0.0],
            "rest_position": [3.0, 4.0], "collisions_during_return": contacts, "link_cycles": 1}


def _sweep(tmp_path: Path, rows: list[dict]) -> Path:
    out = tmp_path / "sweep"
    out.mkdir()
    pq.write_table(to_table(rows), out / "trials.parquet")
    return out


def test_every_section_of_the_page_names_a_table_and_its_sweep_spec_and_tree():
    ev = _module()
    text = PAGE.read_text(encoding="utf-8")
    lines = text.splitlines()
    begins = [k for k, line in enumerate(lines) if ev.BEGIN.match(line)]
    assert len(begins) >= 7 and lines.count(ev.END) == len(begins)
    inside = {j for k in begins for j in range(k, lines.index(ev.END, k) + 1)}
    by_hand = [j + 1 for j, line in enumerate(lines) if line.startswith("|") and j not in inside]
    assert not by_hand, f"docs/evidence.md has table lines outside a written section: lines {by_hand}"
    for k in begins:
        opts = ev.parse_marker(ev.BEGIN.match(lines[k]).group(1))
        assert opts["table"] in ("family", "builtin", "seek", "compare", "drive", "spread") and opts["sweep"], lines[k]
        assert all((ROOT / spec).is_file() for spec in opts["spec"].split(",")), lines[k]
        assert re.fullmatch(r"[0-9a-f]{7,40}", opts["tree"]), lines[k]
        end = lines.index(ev.END, k)
        assert any(line.startswith("| ") for line in lines[k:end]), lines[k]  # the table itself
        assert any(opts["tree"] in line for line in lines[k + 1:end]), lines[k]  # said under the table, too
    assert ev.rewrite(text, {}, "0000000")[0] == text  # no sweep given: nothing changes


def test_the_script_writes_a_section_from_its_sweep_and_leaves_the_others(tmp_path):
    ev = _module()
    rows = [_row(s, "rover", "returnlink", 5.0 + 0.1 * s) for s in range(20)]
    rows += [_row(s, "rover", "smartrtl", None if s >= 18 else 7.0, contacts=1) for s in range(20)]
    doc = tmp_path / "evidence.md"
    doc.write_text("# page\n\n"
                   "<!-- evidence: table=compare sweep=tiny rows=tunnel policies=returnlink,smartrtl spec=s.toml "
                   "tree=abc1234 -->\nold figures\n<!-- /evidence -->\n\n"
                   "<!-- evidence: table=seek sweep=other spec=s.toml tree=abc1234 -->\nkept\n<!-- /evidence -->\n")
    code = ev.main([f"tiny={_sweep(tmp_path, rows)}", "--doc", str(doc), "--tree", "def5678"])
    text = doc.read_text()
    assert code == 0 and "old figures" not in text and "\nkept\n" in text
    mine = next(line for line in text.splitlines() if line.startswith("| tunnel | rover | returnlink "))
    p50, p95 = (percentile([5.0 + 0.1 * s for s in range(20)], q) for q in (50, 95))
    assert mine == f"| tunnel | rover | returnlink | 1.0 | 20/20 | {p50:.1f} / {p95:.1f} s | 5.0 m | 0 |"
    theirs = next(line for line in text.splitlines() if line.startswith("| tunnel | rover | smartrtl "))
    assert "| 7.0 s / never |" in theirs and theirs.endswith("| 20 |") and "| 0.9 | 18/20 |" in theirs
    assert "tree=def5678" in text and "on tree `def5678` (40 trials, 0 errors)" in text


def test_a_marker_it_cannot_follow_is_named_by_file_and_line(tmp_path, capsys):
    ev = _module()
    sweep = _sweep(tmp_path, [_row(1, "rover", "returnlink", 5.0)])
    doc = tmp_path / "evidence.md"
    doc.write_text("# page\n\n<!-- evidence: table=pie sweep=tiny spec=s.toml tree=abc1234 -->\n<!-- /evidence -->\n")
    assert ev.main([f"tiny={sweep}", "--doc", str(doc)]) == 2
    assert f"{doc}:3: table='pie'" in capsys.readouterr().err
    doc.write_text("<!-- evidence: table=seek sweep=tiny -->\nno end\n")
    assert ev.main([f"tiny={sweep}", "--doc", str(doc)]) == 2
    assert f"{doc}:1: no <!-- /evidence -->" in capsys.readouterr().err
    assert ev.main([f"tiny={tmp_path / 'nowhere'}", "--doc", str(doc)]) == 2


def test_the_spread_pairs_each_trial_with_its_twin_one_tick_away():
    """Issue 38's one-tick spread: a trial and its twin at the other LNK_TIMEOUT give one gap each; a twin that never
    regained is an infinite gap; the before sweep's rows come first, under their own tree."""
    ev = _module()
    def twins(seed: int, ttl: float | None, other: float | None) -> list[dict]:
        return [_row(seed, "rover", "returnlink", ttl, LNK_TIMEOUT=3.0),
                _row(seed, "rover", "returnlink", other, LNK_TIMEOUT=3.02)]

    after = twins(1, 6.0, 6.5) + twins(2, 5.0, 5.0)
    before = twins(1, 6.2, 10.1) + twins(2, 5.0, None)
    assert ev.perturbation_gaps(after, "LNK_TIMEOUT") == {"rover": [0.5, 0.0]}
    gaps = ev.perturbation_gaps(before, "LNK_TIMEOUT")["rover"]
    assert abs(gaps[0] - 3.9) < 1e-9 and gaps[1] == float("inf")
    table = ev.spread_table(after, "LNK_TIMEOUT", before, ("old", "new")).splitlines()
    assert table[2].startswith("| old | rover | 2 |") and table[2].endswith("| never | 2 |"), table[2]
    assert table[3] == "| new | rover | 2 | 0.25 s | 0.50 s | 0.50 s | 0 |", table[3]


def test_the_drive_table_puts_the_drivers_figures_beside_the_returns():
    """Issue 41: contacts in returns, collisions in all and link losses per trial per policy, and each P95 against the
    first policy's on the same scenario."""
    ev = _module()
    rows = [dict(_row(s, "rover", "returnlink", 5.0 + s), collisions=1 if s == 1 else 0) for s in range(1, 3)]
    rows += [dict(_row(s, "ardurover", "companion", 6.0 + s, contacts=s - 1), link_cycles=2) for s in range(1, 3)]
    table = ev.drive_table(rows, None, ["returnlink", "companion"]).splitlines()
    assert table[2] == "| tunnel | rover | returnlink | 2 | 0 | 1 | 1.00 | 7.00 s | 1.00x |", table[2]
    assert table[3] == "| tunnel | ardurover | companion | 2 | 1 | 0 | 2.00 | 8.00 s | 1.14x |", table[3]
