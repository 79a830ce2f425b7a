"""A hand-written TOML file read field by field: typed access to the parsed table that knows where each field was
written, so every error names the file, the line and the field (``ScenarioError``). Scenario files
(``sim.scenario``) are read with it; an unknown key is answered with the closest known one, and NaN or infinity
anywhere is refused (TOML allows them, no field of a scenario does)."""

from __future__ import annotations

import difflib
import math
import re
from typing import Any


class ScenarioError(ValueError):
    def __init__(self, file: str, line: int | None, fld: str, message: str) -> None:
        self.file, self.line, self.field = file, line, fld
        where = f"{file}:{line}" if line else file
        super().__init__(f"{where}: {fld}: {message}" if fld else f"{where}: {message}")


class Reader:
    """Typed access to the parsed TOML that knows where each field was written."""

    def __init__(self, file: str, text: str) -> None:
        self.file, self.lines = file, text.splitlines()

    def line_of(self, path: str) -> int | None:
        """Best-effort line of ``a.b[2].c``: the table header (n-th occurrence for arrays), then the key."""
        parts = re.findall(r"([A-Za-z_]+)(?:\[(\d+)\])?", path)
        start, table = 0, ""
        for k, (name, idx) in enumerate(parts):
            is_last = k == len(parts) - 1
            table = f"{table}.{name}" if table else name
            if idx:
                pat = re.compile(rf"^\s*\[\[\s*{re.escape(table)}\s*\]\]")
                hits = [i for i, ln in enumerate(self.lines) if pat.match(ln)]
                if int(idx) < len(hits):
                    start = hits[int(idx)]
                    continue
                key = re.compile(rf"^\s*{re.escape(name)}\s*=")
                for i in range(start, len(self.lines)):
                    if key.match(self.lines[i]):
                        return self._inline_item(i, int(idx)) + 1
                return start + 1 if start else None
            if is_last:
                key = re.compile(rf"^\s*{re.escape(name)}\s*=")
                for i in range(start, len(self.lines)):
                    if key.match(self.lines[i]):
                        return i + 1
                inline = re.compile(rf"[{{,]\s*{re.escape(name)}\s*=")  # a key of an inline table
                for i in range(start, len(self.lines)):
                    if inline.search(self.lines[i]):
                        return i + 1
                return start + 1 if start else None
            pat = re.compile(rf"^\s*\[\s*{re.escape(table)}\s*\]")
            for i in range(start, len(self.lines)):
                if pat.match(self.lines[i]):
                    start = i
                    break
        return start + 1 if start else None

    def _inline_item(self, i: int, idx: int) -> int:
        """The line of the idx-th ``{...}`` of an inline array whose key is on line ``i`` (or i)."""
        seen = -1
        for j in range(i, len(self.lines)):
            seen += self.lines[j].split("#", 1)[0].count("{")
            if seen >= idx:
                return j
            if j > i and "=" in self.lines[j].split("#", 1)[0] and "{" not in self.lines[j]:
                break  # the next key: the array has fewer items
        return i

    def fail(self, path: str, message: str) -> ScenarioError:
        return ScenarioError(self.file, self.line_of(path), path, message)

    def known(self, d: dict[str, Any], path: str, keys: Any) -> None:
        """Every key of table ``d`` must be one of ``keys``; an unknown one is named with the closest known key."""
        keys = sorted(keys)
        for k in d:
            if k not in keys:
                close = difflib.get_close_matches(k, keys, 1, 0.6)
                hint = f"; did you mean {close[0]!r}?" if close else ""
                raise self.fail(f"{path}.{k}" if path else k,
                                f"unknown field{hint} (expected one of {', '.join(keys)})")

    def finite(self, v: Any, path: str) -> None:
        """NaN or infinity anywhere in the file is an error: TOML allows them, no field of a scenario does."""
        if isinstance(v, float) and not math.isfinite(v):
            raise self.fail(path, f"must be a finite number, got {v}")
        if isinstance(v, dict):
            for k, x in v.items():
                self.finite(x, f"{path}.{k}" if path else k)
        elif isinstance(v, list):
            for k, x in enumerate(v):
                # arrays of tables are addressed by index; a number inside a list of points by the list's key
                self.finite(x, f"{path}[{k}]" if isinstance(x, dict) else path)

    def table(self, d: dict[str, Any], key: str, path: str, keys: Any, default: Any = ...) -> dict[str, Any]:
        """A sub-table whose keys must all be known."""
        v = self.get(d, key, path, dict, default)
        if isinstance(v, dict):
            self.known(v, path, keys)
        return v

    def tables(self, d: dict[str, Any], key: str, path: str, keys: Any) -> list[dict[str, Any]]:
        """An array of tables whose keys must all be known."""
        out = self.get(d, key, path, list, [])
        for k, v in enumerate(out):
            if not isinstance(v, dict):
                raise self.fail(f"{path}[{k}]", f"must be a table, got {v!r}")
            self.known(v, f"{path}[{k}]", keys)
        return out

    def get(self, d: dict[str, Any], key: str, path: str, kind: type | tuple[type, ...], default: Any = ...) -> Any:
        if key not in d:
            if default is ...:
                raise self.fail(path, "is required")
            return default
        v = d[key]
        if kind is float and isinstance(v, int) and not isinstance(v, bool):
            v = float(v)
        if not isinstance(v, kind) or (kind is int and isinstance(v, bool)):
            names = kind.__name__ if isinstance(kind, type) else " or ".join(k.__name__ for k in kind)
            raise self.fail(path, f"must be {names}, got {type(v).__name__} {v!r}")
        if isinstance(v, float) and not math.isfinite(v):
            raise self.fail(path, "must be finite")
        return v

    def number(self, d: dict[str, Any], key: str, path: str, default: Any = ..., lo: float = -math.inf,
               hi: float = math.inf) -> float:
        v = self.get(d, key, path, float, default)
        if v is not None and not lo <= v <= hi:
            raise self.fail(path, f"must be within {lo}..{hi}, got {v}")
        return v

    def point(self, v: Any, path: str, n: int = 2) -> tuple[float, ...]:
        if (not isinstance(v, list) or len(v) != n
                or not all(isinstance(c, (int, float)) and not isinstance(c, bool) for c in v)):
            raise self.fail(path, f"must be a list of {n} numbers, got {v!r}")
        return tuple(float(c) for c in v)

    def points(self, d: dict[str, Any], key: str, path: str, n: int = 2, min_len: int = 2) -> tuple:
        v = self.get(d, key, path, list)
        if len(v) < min_len:
            raise self.fail(path, f"needs at least {min_len} points")
        return tuple(self.point(p, f"{path}", n) for p in v)
