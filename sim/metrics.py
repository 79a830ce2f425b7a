"""The figures of one run (DESIGN §7: the keys of metrics.json are a contract) and the scenario's verdict."""

from __future__ import annotations

import math

import numpy as np

from sim.runner import Run

KEYS = ("scenario", "vehicle", "seed", "sim_duration_s", "link_lost_s", "return_started_s", "reaction_latency_s",
        "link_regained_s", "distance_back_m", "max_displacement_m", "final_target_error_m", "collisions",
        "stale_commands_executed", "commands_rejected", "estimator_rmse_m", "trail_points",
        "trail_max_deviation_m", "real_time_factor", "lease_events", "passed", "failures")
DISPLACEMENT_SLACK = 0.5  # m of path-tracking overshoot tolerated at the displacement circle


def _r(x: float | None, nd: int = 3) -> float | None:
    return None if x is None or not math.isfinite(x) else round(float(x), nd)


def path_deviation(path: np.ndarray, poly: np.ndarray) -> float:
    """Largest distance from any point of ``path`` to the polyline ``poly``."""
    if len(path) == 0 or len(poly) == 0:
        return 0.0
    if len(poly) == 1:
        return float(np.max(np.hypot(*(path - poly[0]).T)))
    a, b = poly[:-1], poly[1:]
    ab = b - a
    L2 = np.maximum((ab**2).sum(axis=1), 1e-18)
    worst = 0.0
    for chunk in np.array_split(path, max(1, len(path) // 512)):
        ap = chunk[:, None, :] - a[None, :, :]
        u = np.clip((ap * ab[None]).sum(axis=2) / L2[None], 0.0, 1.0)
        d = np.hypot(*(ap - u[..., None] * ab[None]).transpose(2, 0, 1))
        worst = max(worst, float(d.min(axis=1).max()))
    return worst


def compute(run: Run) -> dict:
    v, sc, tr = run.vehicle, run.scenario, run.trace
    events = run.lease_events
    timeout = v.params["LNK_TIMEOUT"]
    first_return = next((e for e in v.event_log if e.current is not None and _holder_is_service(e)), None)
    lost = run.losses[0] if run.losses else None
    reaction = None
    comms_return = next((e for e in v.event_log if e.reason.name == "COMMS_LOST" and _holder_is_service(e)), None)
    if comms_return is not None:
        heard = next((h for t, h in run.losses if abs(t - comms_return.t) < 1e-9), None)
        if heard is not None:
            reaction = comms_return.t - heard - timeout
    # the link counts as back when the vehicle says so: LINK_REGAINED ending a block, or after a block completed
    regained = run.link_backs[0][0] if run.link_backs else None
    blocks = run.blocks
    distance_back = sum(b.distance for b in blocks)
    max_disp = max((b.max_disp for b in blocks), default=0.0)
    final_err = None
    first = blocks[0] if blocks else None
    if first is not None and first.end is not None:
        if first.reason == "LINK_REGAINED" and run.regains and run.regains[0][1] is not None:
            # halted because the link came back: the place that matters is where it came back
            final_err = math.dist(first.end, run.true_at(run.regains[0][1]))
        elif first.target is not None:
            final_err = math.dist(first.end, first.target)
    true, est = np.array(tr.true), np.array(tr.est)
    rmse = float(np.sqrt(np.mean(np.sum((true - est) ** 2, axis=1)))) if len(true) else 0.0
    poly = np.vstack([v.trail.points(), [[v.estimator.pose.x, v.estimator.pose.y]]])
    deviation = path_deviation(est[::5], poly)
    m = {
        "scenario": sc.name, "vehicle": run.kind, "seed": run.seed, "sim_duration_s": _r(run.t, 2),
        "link_lost_s": _r(lost[1] if lost else None), "return_started_s": _r(first_return.t if first_return else None),
        "reaction_latency_s": _r(reaction, 4), "link_regained_s": _r(regained),
        "distance_back_m": _r(distance_back, 2), "max_displacement_m": _r(max_disp, 2),
        "final_target_error_m": _r(final_err, 2), "collisions": run.world.collisions,
        "stale_commands_executed": v.stale_commands_executed + run.audit_stale,
        "commands_rejected": v.commands_rejected,
        "estimator_rmse_m": _r(rmse), "trail_points": v.trail.count, "trail_max_deviation_m": _r(deviation),
        "real_time_factor": _r(run.t / run.wall if run.wall > 0 else None, 1), "lease_events": events,
    }
    failures = verdict(run, m)
    m["passed"] = not failures
    m["failures"] = failures
    assert tuple(m) == KEYS
    return m


def _holder_is_service(e) -> bool:
    return e.holder.name == "RETURN_SERVICE"


def verdict(run: Run, m: dict) -> list[str]:
    """The scenario's own success criteria, each failure said in words."""
    c = run.scenario.criteria
    out = []
    if m["stale_commands_executed"]:
        out.append(f"{m['stale_commands_executed']} stale commands executed")
    if c.return_started is not None and (m["return_started_s"] is not None) != c.return_started:
        out.append("no return started" if c.return_started else "a return started")
    if c.link_regained is not None and (m["link_regained_s"] is not None) != c.link_regained:
        out.append("link never regained after the loss" if c.link_regained else "link regained")
    if c.max_final_target_error_m is not None and m["final_target_error_m"] is not None \
            and m["final_target_error_m"] > c.max_final_target_error_m:
        out.append(f"final target error {m['final_target_error_m']} m > {c.max_final_target_error_m} m")
    if c.max_final_target_error_m is not None and m["final_target_error_m"] is None and c.return_started:
        out.append("no return target to measure against")
    if m["collisions"] > c.max_collisions:
        out.append(f"{m['collisions']} collisions > {c.max_collisions}")
    if c.max_displacement_respected:
        for b in run.blocks:
            if b.max_disp > b.max_disp_allowed + DISPLACEMENT_SLACK:
                out.append(f"lease {b.index}: displacement {b.max_disp:.2f} m > limit {b.max_disp_allowed:.2f} m")
    if c.min_distance_back_m is not None and m["distance_back_m"] < c.min_distance_back_m:
        out.append(f"distance back {m['distance_back_m']} m < {c.min_distance_back_m} m")
    if m["commands_rejected"] < c.min_commands_rejected:
        out.append(f"{m['commands_rejected']} commands rejected < {c.min_commands_rejected}")
    if c.chain_reasons:
        got = [b.reason for b in run.blocks]
        if got[:len(c.chain_reasons)] != list(c.chain_reasons):
            out.append(f"return blocks ended {got}, expected {list(c.chain_reasons)}")
    return out


def summary(run: Run, m: dict) -> str:
    def f(x, unit="", nd=1):
        return "-" if x is None else f"{x:.{nd}f}{unit}"

    lines = [
        f"returnlink sim run {m['scenario']} --vehicle {m['vehicle']} --seed {m['seed']}",
        f"  simulated {f(m['sim_duration_s'], ' s')} at {f(m['real_time_factor'], 'x real time')}",
        f"  link lost at {f(m['link_lost_s'], ' s')}, return began {f(m['return_started_s'], ' s')}"
        f" (reaction {f(m['reaction_latency_s'], ' s', 3)} after LNK_TIMEOUT)",
        f"  link regained at {f(m['link_regained_s'], ' s')}; drove {f(m['distance_back_m'], ' m')} back,"
        f" max displacement {f(m['max_displacement_m'], ' m')}, target error {f(m['final_target_error_m'], ' m', 2)}",
        f"  collisions {m['collisions']}, stale commands executed {m['stale_commands_executed']},"
        f" commands rejected {m['commands_rejected']}",
        f"  estimator RMSE {f(m['estimator_rmse_m'], ' m', 2)}, trail {m['trail_points']} points"
        f" (max deviation {f(m['trail_max_deviation_m'], ' m', 2)})",
        "  lease events:",
    ]
    for e in m["lease_events"]:
        lines.append(f"    {e['t']:7.2f} s  {e['expired']} -> {e['current']}  {e['reason']}")
    lines.append("  PASSED" if m["passed"] else "  FAILED: " + "; ".join(m["failures"]))
    return "\n".join(lines)
