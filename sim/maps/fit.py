"""`returnlink site fit`: the radio model's parameters from a real drive's log.

The model is ``link.radio``'s mean channel on the map's grid (``sim.maps.grid``):

    rssi = power - ref_loss_db - 10 exponent log10(d) - wall_db runs - wall_db_per_m metres + shadowing

with ``runs`` and ``metres`` the solid cells crossed on the line of sight from the station. It is linear in the four
parameters, so with a signal strength along the way (RADIO_STATUS, SiK units: dBm = rssi / 1.9 - 127) the fit is
least squares (SciPy's bounded solver: no negative wall loss, an exponent of 1..6), and ``shadowing_db`` is the
residuals' spread. Shadowing is correlated over metres, so neighbouring samples are not independent: the
uncertainty is that of a fit over the places visited (``PLACE_M`` squares, each one observation), not the naive one that
would claim far too much. Without RADIO_STATUS the signal is the delivery of a 1 Hz heartbeat along the way (the
vehicle's as the station heard it, or the station's as the vehicle heard it), fitted by maximum likelihood through
the radio's delivery curve, its uncertainty from the likelihood's curvature.

Positions come from LOCAL_POSITION_NED, which a `sim run map:...` log holds in the map's own frame (north = map y,
east = map x), or from GLOBAL_POSITION_INT about ``--anchor`` (the map origin's latitude and longitude).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from link.radio import RadioParams
from link.storage import write_atomic
from sim.maps.grid import Grid, Site
from sim.world import Station

PLACE_M = 3.0  # m: the squares whose samples count as one place (shadowing is one draw over a few metres)
FRESH_S = 1.0  # s: a position older than this at a signal sample is no position
MIN_SAMPLES = 20
EARTH_R = 6378137.0
PARAMS = ("ref_loss_db", "exponent", "wall_db", "wall_db_per_m")
# a standard error above this says the drive cannot tell the parameter (a log with little signal: the estimate
# stays where the fit started, and is reported as not identified)
IDENTIFIED = {"ref_loss_db": 10.0, "exponent": 1.0, "wall_db": 20.0, "wall_db_per_m": 20.0}
BOUNDS = {"ref_loss_db": (0.0, 200.0), "exponent": (1.0, 6.0), "wall_db": (0.0, 200.0), "wall_db_per_m": (0.0, 200.0)}


class FitError(ValueError):
    """A log that cannot be fitted: the message names the file and what is missing."""


@dataclass(frozen=True)
class Samples:
    """Signal samples along a drive: where (world frame), what the line of sight crosses, and the signal."""

    kind: str  # "rssi" (dBm) or "delivery" (1 delivered / 0 lost)
    t: np.ndarray  # s, the log's time
    north: np.ndarray
    east: np.ndarray
    dist: np.ndarray
    runs: np.ndarray
    metres: np.ndarray
    value: np.ndarray


@dataclass(frozen=True)
class Fit:
    """Each parameter's estimate and standard error (nan: not identified by this drive, kept at its default)."""

    estimate: dict[str, float]
    stderr: dict[str, float]
    shadowing_db: float
    shadowing_se: float
    residuals: np.ndarray
    kind: str


def _positions(log, anchor) -> tuple[np.ndarray, np.ndarray, np.ndarray, int | None]:
    local = [(t, m.x, m.y, src) for t, m, src in log if m.get_type() == "LOCAL_POSITION_NED"]
    if local:
        a = np.array([r[:3] for r in local])
        return a[:, 0], a[:, 1], a[:, 2], local[0][3]
    glob = [(t, m.lat / 1e7, m.lon / 1e7, src) for t, m, src in log if m.get_type() == "GLOBAL_POSITION_INT"]
    if glob and anchor is None:
        raise FitError("its positions are GLOBAL_POSITION_INT only: give --anchor LAT,LON (the map origin's place)")
    if not glob:
        raise FitError("holds no positions (LOCAL_POSITION_NED or GLOBAL_POSITION_INT)")
    a = np.array([r[:3] for r in glob])
    lat0, lon0 = math.radians(anchor[0]), math.radians(anchor[1])
    north = (np.radians(a[:, 1]) - lat0) * EARTH_R
    east = (np.radians(a[:, 2]) - lon0) * EARTH_R * math.cos(lat0)
    return a[:, 0], north, east, glob[0][3]


def _read(path: Path):
    """(time, message, source system id) of every frame of a .tlog."""
    import os

    from pymavlink import mavutil

    os.environ.setdefault("MAVLINK20", "1")  # a returnlink log is MAVLink 2: pymavlink reads v2 only when told
    try:
        conn = mavutil.mavlink_connection(str(path), dialect="returnlink", robust_parsing=True)
    except OSError as e:
        raise FitError(f"cannot read it: {e.strerror or e}") from None
    out = []
    while True:
        try:
            m = conn.recv_match()
        except Exception:  # noqa: BLE001 - pymavlink raises bare errors for a cut-off file: the end of the log
            break
        if m is None:
            break
        if m.get_type() == "BAD_DATA":
            continue
        out.append((float(getattr(m, "_timestamp", 0.0)), m, m.get_srcSystem()))
    return out


def samples_from_tlog(path: Path, grid: Grid, site: Site, station: Station, anchor=None) -> Samples:
    """The drive's signal samples on the map; FitError (naming the file) when it has no positions or signal."""
    try:
        log = _read(path)
        pt, pn, pe, vehicle = _positions(log, anchor)
    except FitError as e:
        raise FitError(f"{path}: {e}") from None
    order = np.argsort(pt, kind="stable")
    pt, pn, pe = pt[order], pn[order], pe[order]
    radio = [(t, m.rssi) for t, m, _ in log if m.get_type() == "RADIO_STATUS" and m.rssi not in (0, 255)]
    if radio:
        t = np.array([r[0] for r in radio])
        value = np.array([r[1] for r in radio], dtype=float) / 1.9 - 127.0
        k = np.searchsorted(pt, t, side="right") - 1
        after = np.minimum(k + 1, len(pt) - 1)
        # a sample between two positions no more than FRESH_S apart, at the place interpolated for its time
        ok = (k >= 0) & (pt[after] - pt[np.maximum(k, 0)] <= FRESH_S) & (t <= pt[-1])
        t, value = t[ok], value[ok]
        kind, north, east = "rssi", np.interp(t, pt, pn), np.interp(t, pt, pe)
    else:
        kind, north, east, value, t = _heartbeat_delivery(log, vehicle, pt, pn, pe)
        if kind is None:
            raise FitError(f"{path}: holds no signal: no RADIO_STATUS and no 1 Hz heartbeat to count")
    if len(value) < MIN_SAMPLES:
        raise FitError(f"{path}: only {len(value)} signal samples with a position (at least {MIN_SAMPLES} needed)")
    runs = np.zeros(len(value))
    metres = np.zeros(len(value))
    for i, (n, e) in enumerate(zip(north.tolist(), east.tolist(), strict=True)):
        runs[i], metres[i] = grid.crossed((station.x, station.y), (n, e))
    dist = np.maximum(1.0, np.hypot(north - station.x, east - station.y))
    return Samples(kind, t, north, east, dist, runs, metres, value)


def _heartbeat_delivery(log, vehicle, pt, pn, pe):
    """1 for each heartbeat heard, 0 for each one missed, at the drive's position then (interpolated): the
    station's heartbeats in a log the vehicle kept, else the vehicle's in a log the station kept."""
    beats: dict[int, list[float]] = {}
    for t, m, src in log:
        if m.get_type() == "HEARTBEAT":
            beats.setdefault((src, m.type == 6), []).append(t)
    gcs = [k for k in beats if k[1] and k[0] != vehicle]
    key = gcs[0] if gcs else next((k for k in beats if k[0] == vehicle), None)
    if key is None or len(beats[key]) < 3:
        return None, None, None, None, None
    t = np.array(sorted(beats[key]))
    period = float(np.median(np.diff(t)))
    if not 0.2 <= period <= 5.0:
        return None, None, None, None, None
    slots, heard = [], []
    for a, b in zip(t[:-1].tolist(), t[1:].tolist(), strict=True):
        missed = max(0, round((b - a) / period) - 1)
        slots += [a] + [a + period * (j + 1) for j in range(missed)]
        heard += [1.0] + [0.0] * missed
    slots, heard = np.array(slots), np.array(heard)
    inside = (slots >= pt[0]) & (slots <= pt[-1])
    slots = slots[inside]
    return "delivery", np.interp(slots, pt, pn), np.interp(slots, pt, pe), heard[inside], slots


def _design(s: Samples, power: float) -> tuple[np.ndarray, np.ndarray]:
    """y = X beta with beta = (ref_loss_db, exponent, wall_db, wall_db_per_m)."""
    x = np.stack([-np.ones(len(s.dist)), -10.0 * np.log10(s.dist), -s.runs, -s.metres], axis=1)
    return x, s.value - power


def _clusters(s: Samples) -> np.ndarray:
    """The place (a PLACE_M square) of each sample: samples at one place share one shadowing draw."""
    return np.floor(s.north / PLACE_M).astype(np.int64) * 1_000_003 + np.floor(s.east / PLACE_M).astype(np.int64)


def fit(s: Samples, prior: RadioParams, power: float) -> Fit:
    """The parameters, their standard errors and the residuals. A parameter the drive cannot tell (no sample
    behind a wall: no wall loss to see) keeps ``prior``'s value or the map default, with a nan error."""
    x, y = _design(s, power)
    free = [bool(np.ptp(x[:, k]) > 1e-9) or k == 0 for k in range(4)]
    if s.kind == "rssi":
        beta, cov, resid = _least_squares(x, y, free, _clusters(s))
        sigma = float(np.std(resid, ddof=int(sum(free))))
        n_eff = max(2, len(np.unique(_clusters(s))))  # places
        sigma_se = sigma / math.sqrt(2 * n_eff)
    else:
        beta, cov, resid = _likelihood(x, s.value, free, prior, power, _clusters(s))
        sigma, sigma_se = prior.shadowing_db, math.nan
    est = {p: float(beta[k]) for k, p in enumerate(PARAMS)}
    se = {p: float(math.sqrt(max(cov[k, k], 0.0))) if free[k] else math.nan for k, p in enumerate(PARAMS)}
    for p in PARAMS:  # a spread wider than the parameter could ever need: the drive does not tell it
        if not se[p] <= IDENTIFIED[p]:
            se[p] = math.nan
            est[p] = getattr(prior, p, est[p]) if p in ("ref_loss_db", "exponent") else est[p]
    return Fit(est, se, sigma, sigma_se, resid, s.kind)


def _least_squares(x, y, free, clusters):
    """Bounded least squares over the places the drive visited: each place (``_clusters``) is one observation,
    the mean of its samples, since a robot that stands still at the start or behind a wall adds samples of one
    shadowing draw, not information. The standard errors are the ordinary ones of that regression."""
    from scipy.optimize import lsq_linear

    cols = [k for k in range(4) if free[k]]
    lo = [BOUNDS[PARAMS[k]][0] for k in cols]
    hi = [BOUNDS[PARAMS[k]][1] for k in cols]
    places, index = np.unique(clusters, return_inverse=True)
    count = np.bincount(index).astype(float)
    xm = np.stack([np.bincount(index, weights=x[:, k]) / count for k in cols], axis=1)
    ym = np.bincount(index, weights=y) / count
    b = lsq_linear(xm, ym, bounds=(lo, hi)).x
    # the spread: that of the same regression without the bounds (an estimate held at a bound is no more
    # certain than the data make it)
    free_b = np.linalg.lstsq(xm, ym, rcond=None)[0]
    resid_m = ym - xm @ free_b
    dof = len(places) - len(cols)
    if dof > 0:
        cov_small = float(resid_m @ resid_m) / dof * np.linalg.pinv(xm.T @ xm)
    else:  # as many places as parameters: nothing to judge the fit by
        cov_small = np.diag(np.full(len(cols), math.inf))
    beta, cov = np.zeros(4), np.zeros((4, 4))
    for j, k in enumerate(cols):
        beta[k] = b[j]
        for i, m in enumerate(cols):
            cov[k, m] = cov_small[j, i]
    return beta, cov, y - x[:, cols] @ b


def _likelihood(x, delivered, free, prior: RadioParams, power: float, clusters):
    """Maximum likelihood of heard and missed heartbeats through the radio's delivery curve (its threshold and
    fade width as ``prior`` has them), with the cluster-robust covariance of the score."""
    from scipy.optimize import minimize

    thr = max(prior.sensitivity_dbm, prior.noise_floor_dbm + 5.0)
    width = max(1e-6, prior.fade_width_db / 4.0)
    cols = [k for k in range(4) if free[k]]
    xs = -x[:, cols]  # loss = xs @ beta (x was written with the signs of the received power)
    start = np.array([prior.ref_loss_db, prior.exponent, 8.0, 4.0])[cols]

    def logits(b):
        return (power - xs @ b - thr) / width

    def nll(b):
        z = logits(b)
        # -log sigmoid(z) for a heard beat, -log(1 - sigmoid(z)) for a missed one, without overflow
        return float(np.sum(np.logaddexp(0.0, -z) * delivered + np.logaddexp(0.0, z) * (1.0 - delivered)))

    def grad(b):
        p = 1.0 / (1.0 + np.exp(-np.clip(logits(b), -700, 700)))
        return ((p - delivered)[:, None] * (-xs / width)).sum(axis=0) * -1.0

    res = minimize(nll, start, jac=grad, method="L-BFGS-B", bounds=[BOUNDS[PARAMS[k]] for k in cols])
    b = res.x
    p = 1.0 / (1.0 + np.exp(-np.clip(logits(b), -700, 700)))
    j = -xs / width  # d logit / d beta
    info = (j * (p * (1.0 - p))[:, None]).T @ j
    bread = np.linalg.pinv(info)
    meat = np.zeros_like(info)
    for c in np.unique(clusters):
        g = ((delivered - p)[clusters == c, None] * j[clusters == c]).sum(axis=0)
        meat += np.outer(g, g)
    cov_small = bread @ meat @ bread
    beta, cov = np.zeros(4), np.zeros((4, 4))
    for a, k in enumerate(cols):
        beta[k] = b[a]
        for c, m in enumerate(cols):
            cov[k, m] = cov_small[a, c]
    return beta, cov, delivered - p


def write(result: Fit, s: Samples, out: Path) -> list[Path]:
    """``radio.toml`` (a [radio] table for --radio) and ``fit.png`` (measured against predicted)."""
    lines = [f"# written by returnlink site fit from {len(s.value)} {result.kind} samples: estimate +- standard error",
             "[radio]"]
    for p in PARAMS:
        e, se = result.estimate[p], result.stderr[p]
        note = "not identified by this drive" if math.isnan(se) else f"+- {se:.3g}"
        lines.append(f"{p} = {e!r}  # {note}")
    if result.kind == "rssi":
        lines.append(f"shadowing_db = {result.shadowing_db!r}  # spread of the residuals")
    radio = out / "radio.toml"
    write_atomic(radio, ("\n".join(lines) + "\n").encode("utf-8"))
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sim.plots import save

    fig, ax = plt.subplots(figsize=(7, 4.5))
    predicted = s.value - result.residuals if result.kind == "rssi" else None
    if predicted is not None:
        ax.scatter(s.dist, s.value, s=6, label="measured RSSI", color="tab:blue")
        ax.scatter(s.dist, predicted, s=6, label="fitted model", color="tab:orange")
        ax.set_ylabel("RSSI (dBm)")
    else:
        ax.scatter(s.dist, s.value, s=6, label="heartbeat heard (1) or missed (0)", color="tab:blue")
        ax.scatter(s.dist, s.value - result.residuals, s=6, label="fitted delivery", color="tab:orange")
        ax.set_ylabel("delivery")
    ax.set_xlabel("distance from the station (m)")
    ax.legend(fontsize=8)
    ax.set_title("site fit: the drive's signal against the fitted radio model", fontsize=9)
    return [radio, save(fig, out / "fit.png")]


def report_lines(result: Fit, s: Samples) -> list[str]:
    out = [f"returnlink: fitted {len(s.value)} {result.kind} samples ({int((s.runs > 0).sum())} behind walls)"]
    for p in PARAMS:
        se = result.stderr[p]
        out.append(f"  {p:14s} {result.estimate[p]:9.3f}  " + ("(not identified: kept)" if math.isnan(se)
                                                                 else f"+- {se:.3f}"))
    out.append(f"  {'shadowing_db':14s} {result.shadowing_db:9.3f}  " +
               ("" if math.isnan(result.shadowing_se) else f"+- {result.shadowing_se:.3f}"))
    if len(result.residuals):
        r = result.residuals
        out.append(f"  residuals: mean {np.mean(r):+.2f}, rms {np.sqrt(np.mean(r * r)):.2f}, "
                   f"5-95 % {np.percentile(r, 5):+.2f} .. {np.percentile(r, 95):+.2f}")
    return out


