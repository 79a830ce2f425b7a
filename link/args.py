"""argparse types that range-check MAVLink ids, UDP ports, durations and seeds where they are typed.

``--sysid 300`` used to pass argparse and end in a struct error deep inside pymavlink; a port of 99999 in a
socket error. Each type here raises ``argparse.ArgumentTypeError`` with the allowed range instead, so argparse
prints it and exits 2. Shared by ``returnlink sim`` and ``returnlink gcs``.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable


def integer(lo: int, hi: int, what: str) -> Callable[[str], int]:
    def parse(text: str) -> int:
        try:
            v = int(text, 0)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a whole number ({what}: {lo}..{hi})") from None
        if not lo <= v <= hi:
            raise argparse.ArgumentTypeError(f"{what} must be within {lo}..{hi}, got {v}")
        return v
    parse.__name__ = what  # argparse names the type in its messages
    return parse


def number(what: str, lo: float = -math.inf, hi: float = math.inf, lo_open: bool = False,
           allow_inf: bool = False) -> Callable[[str], float]:
    """A float within lo..hi (or lo < v with ``lo_open``); NaN never, infinity only with ``allow_inf``."""
    def parse(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number ({what})") from None
        if math.isnan(v) or (math.isinf(v) and not allow_inf):
            raise argparse.ArgumentTypeError(f"{what} must be a finite number, got {text!r}")
        if (lo_open and not v > lo) or not lo <= v <= hi:
            low = f"> {lo:g}" if lo_open else f">= {lo:g}"
            raise argparse.ArgumentTypeError(f"{what} must be {low}" + (f" and <= {hi:g}" if hi < math.inf else "")
                                             + f", got {text}")
        return v
    parse.__name__ = what
    return parse


def point(what: str) -> Callable[[str], tuple[float, float]]:
    """Two finite numbers ``X,Y`` (a place in metres)."""
    def parse(text: str) -> tuple[float, float]:
        parts = text.split(",")
        try:
            x, y = (float(p) for p in parts) if len(parts) == 2 else (math.nan, math.nan)
        except ValueError:
            x = y = math.nan
        if not (math.isfinite(x) and math.isfinite(y)):
            raise argparse.ArgumentTypeError(f"{what} must be X,Y (two finite numbers, metres), got {text!r}")
        return x, y
    parse.__name__ = what
    return parse


SYSID = integer(1, 255, "system id")
COMPID = integer(1, 255, "component id")
PORT = integer(1, 65535, "port")
LISTEN_PORT = integer(0, 65535, "port")  # 0: any free port
SEED = integer(0, 2**32 - 1, "seed")
STATION = point("station")  # a map's frame: x east, y north
SECONDS = number("seconds", 0.0, lo_open=True)
SECONDS_OR_INF = number("seconds", 0.0, lo_open=True, allow_inf=True)
SPEEDUP = number("speedup", 0.0, lo_open=True)
VELOCITY = number("velocity (m/s)", -10.0, 10.0)


def address(text: str) -> tuple[str, int]:
    """HOST:PORT with a port 1..65535."""
    host, sep, port = text.rpartition(":")
    if not sep:
        raise argparse.ArgumentTypeError(f"{text!r} is not HOST:PORT")
    return host or "127.0.0.1", PORT(port)


def url(text: str) -> str:
    """A pymavlink UDP url, udpin:HOST:PORT or udpout:HOST:PORT, with a port in range."""
    kind, sep, rest = text.partition(":")
    if not sep or kind not in ("udpin", "udpout"):
        raise argparse.ArgumentTypeError(f"{text!r} is not udpin:HOST:PORT or udpout:HOST:PORT")
    address(rest)  # a port of 1..65535, for udpin as for udpout
    return text
