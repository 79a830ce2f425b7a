"""The README's evidence tables come from benchmarks/generated_evidence.py: its columns must say which robot is
which (an earlier table printed legged's P95 under "rover") and its P95 must be the campaign summary's."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

from sim.campaign.store import percentile

_PATH = Path(__file__).resolve().parent.parent / "benchmarks" / "generated_evidence.py"


def _module():
    spec = importlib.util.spec_from_file_location("generated_evidence", _PATH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _row(vehicle: str, policy: str, ttl: float, contacts: int = 0) -> dict:
    return {"scenario": "gen:mine", "vehicle": vehicle, "policy": policy, "status": "ok", "passed": True,
            "link_lost_s": 10.0, "link_regained_s": 10.0 + ttl, "regained_by": "return",
            "loss_position": json.dumps([0.0, 0.0]), "rest_position": json.dumps([3.0, 4.0]),
            "collisions_during_return": contacts}


def test_each_robots_p95_sits_under_its_own_name_and_pooled_is_the_summarys():
    ev = _module()
    rows = [_row("rover", "returnlink", 5.0 + 0.01 * k) for k in range(20)]
    rows += [_row("legged", "returnlink", 9.0 + 0.01 * k, contacts=1 if k == 0 else 0) for k in range(20)]
    rows += [_row("rover", "backup", 6.0) for _ in range(20)] + [_row("legged", "backup", 6.0) for _ in range(20)]
    table, pooled = ev.family_table(rows, "gen:mine")
    line = next(x for x in table.splitlines() if x.startswith("| returnlink "))
    cells = [c.strip() for c in line.split("|")]
    both, rover, legged = (float(v) for v in cells[6].split(" / "))
    assert rover == round(percentile([5.0 + 0.01 * k for k in range(20)], 95), 2) < 6.0
    assert legged == round(percentile([9.0 + 0.01 * k for k in range(20)], 95), 2) > 9.0
    pooled_rl = percentile([r["link_regained_s"] - r["link_lost_s"] for r in rows if r["policy"] == "returnlink"], 95)
    assert both == round(pooled["returnlink"], 2) and pooled["returnlink"] == pooled_rl
    assert cells[4] == "40/40" and cells[5] == "40/40" and cells[7] == "5.00 m" and cells[8] == "1"
    assert pooled["backup"] == 6.0
