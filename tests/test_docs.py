"""docs/architecture.md is the project's own design document: every section the code cites exists in it, and its
parameter table is the contract table of link/parameters.py, not a copy that drifts."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

from link.parameters import SPECS

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "architecture.md"
CITE = re.compile(r"docs/architecture\.md ((?:§\d+(?:\.\d+)?(?:-(?:§)?\d+(?:\.\d+)?)?(?:,? (?:and )?)?)+)")


def _sections(text: str) -> dict[str, str]:
    """Each numbered section's text by its number ("3", "4.1")."""
    out: dict[str, str] = {}
    parts = re.split(r"^(#{2,3}) (\d+(?:\.\d+)?)\.? ", text, flags=re.M)
    for k in range(1, len(parts), 3):
        out[parts[k + 1]] = parts[k + 2]
    return out


def _exists(ref: str, sections: dict[str, str]) -> bool:
    if ref in sections:
        return True
    top, _, sub = ref.partition(".")
    # a numbered rule of a section (§3.4 is rule 4 of section 3)
    return bool(sub) and top in sections and re.search(rf"^{sub}\. ", sections[top], flags=re.M) is not None


def test_every_section_the_code_cites_exists():
    sections = _sections(DOC.read_text(encoding="utf-8"))
    files = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout.split()
    cited: dict[str, set[str]] = {}
    for name in files:
        path = ROOT / name
        if path.suffix not in (".py", ".md", ".toml") or not path.is_file():
            continue
        for m in CITE.finditer(path.read_text(encoding="utf-8")):
            for ref in re.findall(r"\d+(?:\.\d+)?", m.group(1)):
                cited.setdefault(ref, set()).add(name)
    assert "3.4" in cited and "4.1" in cited  # the search itself finds citations
    missing = {ref: sorted(where) for ref, where in cited.items() if not _exists(ref, sections)}
    assert not missing


def test_the_parameter_table_is_the_contract_table():
    section = _sections(DOC.read_text(encoding="utf-8"))["5"]
    rows = [[c.strip() for c in line.strip().strip("|").split("|")]
            for line in section.splitlines() if re.match(r"\| [A-Z_]+ \|", line)]
    assert [r[0] for r in rows] == [s.name for s in SPECS]
    for (name, default, span, units, meaning), s in zip(rows, SPECS, strict=True):
        lo, hi = span.split("–")
        written = (float(default), float(lo), float(hi), units, meaning)
        assert written == (s.default, s.lo, s.hi, s.units, s.meaning), name
