"""The figures of one run (docs/architecture.md §7: the keys of metrics.json are a contract) and the scenario's verdict.

One pipeline for every plant (``compute``): the run's own figures (who flew what, for how long, how fast), the
§7 figures only the plant's record can give (``Plant.figures``: from the lease record for a plant that flies
returnlink's leases, ``lease_figures``; from its mode timeline for the firmware alone, ``sim.firmware.metrics``),
any keys of the plant's own after them (the firmware's version and modes), and one verdict over them (``verdict``).

Positions are compared in one frame, the true one (the simulator's ground truth): the loss and rest positions,
distances and displacements, and the return target, which the vehicle chose in its estimate frame, is taken as
where the robot truly was when it laid that crumb. ``frames`` in metrics.json says this per key.
"""

from __future__ import annotations

import math

import numpy as np

from vehicle.core import DT, State
from vehicle.link_watch import GOOD_QUALITY as GOOD_LINK_QUALITY

KEYS = ("scenario", "vehicle", "seed", "sim_duration_s", "link_lost_s", "return_started_s", "reaction_latency_s",
        "link_regained_s", "distance_back_m", "max_displacement_m", "final_target_error_m", "collisions",
        "stale_commands_executed", "commands_rejected", "estimator_rmse_m", "trail_points",
        "trail_max_deviation_m", "real_time_factor", "lease_events", "passed", "failures",
        # added compatibly (docs/architecture.md §7, §9)
        "policy", "loss_position", "rest_position", "rest_link_quality", "link_cycles", "regained_by",
        "collisions_during_return", "return_speed_mps", "blocks", "frames", "relapses")
FRAMES = {"loss_position": "true", "rest_position": "true", "distance_back_m": "true", "max_displacement_m": "true",
          "final_target_error_m": "true (the target crumb where the robot truly was when it laid it)",
          "blocks": "true", "return_speed_mps": "true"}
REGAIN_MOVED_M = 0.5  # m an operator must have moved the robot after the return for the regain to be its doing
DISPLACEMENT_SLACK = 0.5  # m of path-tracking overshoot tolerated at the displacement circle


def rounded(x: float | None, nd: int = 3) -> float | None:
    """A figure as metrics.json holds it: rounded to ``nd`` decimals, None when there is none (or it is not finite,
    which JSON cannot hold)."""
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


def compute(run) -> dict:
    """metrics.json of a finished ``sim.runner.Run``, whatever its plant: ``KEYS`` in order (each figure the plant
    does not give is a KeyError here, not a silent gap), then the plant's own keys, then the verdict."""
    figures = run.plant.figures(run)
    own = {"scenario": run.scenario.name, "vehicle": run.kind, "seed": run.seed, "sim_duration_s": rounded(run.t, 2),
           "real_time_factor": rounded(run.t / run.wall if run.wall > 0 else None, 1), "passed": True,
           "failures": [], "policy": run.policy}
    m = {k: own[k] if k in own else figures.pop(k) for k in KEYS}
    m.update(figures)
    m["failures"] = verdict(run, m, leases=run.plant.leases)
    m["passed"] = not m["failures"]
    return m


def lease_figures(run) -> dict:
    """The §7 figures of a run whose plant flies returnlink's vehicle (natively, or as the companion beside the
    firmware), from the run's lease record (``sim.lease_record``) and the vehicle's own counters, as its last status
    snapshot shows them."""
    s = run.vehicle.status()
    lost = run.losses[0] if run.losses else None
    first_return, reaction = _return_start(run)
    # the link counts as back when the vehicle says so: LINK_REGAINED ending a block, or after a block completed
    regained = run.link_backs[0][0] if run.link_backs else None
    blocks = run.blocks
    distance_back = sum(b.distance for b in blocks)
    max_disp = max((b.max_disp for b in blocks), default=0.0)
    rmse, est = _estimator_error(run.trace)
    m = {
        "link_lost_s": rounded(lost[1] if lost else None), "return_started_s": rounded(first_return),
        "reaction_latency_s": rounded(reaction, 4), "link_regained_s": rounded(regained),
        "distance_back_m": rounded(distance_back, 2), "max_displacement_m": rounded(max_disp, 2),
        "final_target_error_m": rounded(_final_target_error(run), 2), "collisions": run.world.collisions,
        "stale_commands_executed": s.stale_commands + run.audit_stale,
        "commands_rejected": s.commands_rejected,
        "estimator_rmse_m": rounded(rmse), "trail_points": s.trail_points,
        "trail_max_deviation_m": rounded(_trail_deviation(run, est)), "lease_events": run.lease_events,
    }
    m.update(after_loss(run))
    m["frames"] = dict(FRAMES)
    m["relapses"] = relapses(run.lease_log, run.trace.state)
    return m


def _return_start(run) -> tuple[float | None, float | None]:
    """(when the first return started, how long after its trigger's condition became true it did): the first
    return-service lease, or for a baseline that takes over later than its lease (SmartRTL waits FS_TIMEOUT) when
    it acted; the reaction is measured for the return a COMMS_LOST started, None without one."""
    log = run.lease_log
    first_return = next((e.t for e in log if e.current is not None and _holder_is_service(e)), None)
    comms_return = next((e for e in log if e.reason.name == "COMMS_LOST" and _holder_is_service(e)), None)
    acted = getattr(run.contingency, "acted", None)
    if acted is not None:
        first_return = acted[0] if acted else None
    if comms_return is None:
        return first_return, None
    # from the moment the trigger's condition became true (silence: owner last heard + LNK_TIMEOUT; quality:
    # the delivery estimate falling below LNK_MIN_Q), so the reaction to a quality loss is never negative
    cond = next((c for (t, _), c in zip(run.losses, run.loss_conditions, strict=True)
                 if abs(t - comms_return.t) < 1e-9), None)
    start = comms_return.t if acted is None else next((a for a in acted if a >= comms_return.t - 1e-9), None)
    if cond is not None and start is not None:
        return first_return, start - cond + 0.0
    return first_return, None


def _final_target_error(run) -> float | None:
    """How far from its target the first return block ended: from where the link came back when the block halted
    because it did (the place that matters), else from the block's own target; None if it never ended or had
    none."""
    first = run.blocks[0] if run.blocks else None
    if first is None or first.end is None:
        return None
    if first.reason == "LINK_REGAINED" and run.regains and run.regains[0][1] is not None:
        return math.dist(first.end, run.true_at(run.regains[0][1]))
    if first.target_true is not None:
        return math.dist(first.end, first.target_true)
    return None


def _estimator_error(tr) -> tuple[float, np.ndarray]:
    """(the estimator's RMSE against the truth, its estimates) over the ticks that had an estimate: a tick with
    none yet (the companion before it boots) is not an error of one."""
    true, est = np.array(tr.true), np.array(tr.est)
    if len(est):
        known = np.isfinite(est).all(axis=1)
        true, est = true[known], est[known]
    rmse = float(np.sqrt(np.mean(np.sum((true - est) ** 2, axis=1)))) if len(true) else 0.0
    return rmse, est


def _trail_deviation(run, est: np.ndarray) -> float:
    """How far the estimated path strayed from the trail of crumbs. The trail is in the vehicle's own frame, the
    trace in the true one: ``frame_offset`` is where the first lies in the second (none for the native vehicle,
    whose estimator starts at its true pose)."""
    v = run.vehicle
    pose = v.status().pose
    poly = np.vstack([v.trail_points(), [[pose.x, pose.y]]]) + np.asarray(run.frame_offset)
    return path_deviation(est[::5], poly)


def point(p: tuple[float, float] | None) -> list[float] | None:
    """A position as metrics.json holds it: [x, y] to the millimetre, None when there is none."""
    return None if p is None else [round(float(p[0]), 3), round(float(p[1]), 3)]


def _first_chain_end(run) -> tuple[float | None, int | None]:
    """When the return chain started by the first COMMS_LOST ended (an operator lease current again), and the
    tick index of that moment; (None, None) if it never ended or never started."""
    if not run.losses:
        return None, None
    t_loss = run.losses[0][0]
    tr = run.trace
    k0 = next((k for k, t in enumerate(tr.t) if t >= t_loss - 1e-9), None)
    if k0 is None:
        return None, None
    for k in range(k0, len(tr.t)):
        if tr.holder[k] == 1:  # OPERATOR
            return tr.t[k], k
    return None, None


def after_loss(run) -> dict:
    """The added §7 keys: what the first link loss did, and what the return made of it.

    - ``loss_position``: true position when the owner was last heard before the first COMMS_LOST (the same for
      every policy of a paired trial, which are identical until then).
    - ``rest_position``: true position where the chain of that loss left the robot: at the last tick before an
      operator drove it again (a claimed operator lease), or at the end of the run.
    - ``rest_link_quality``: the owner's packet delivery probability there.
    - ``link_cycles``: number of COMMS_LOST events.
    - ``relapses``: COMMS_LOST events that came after a LINK_REGAINED with no operator driving in between: the
      return stopped where the link came back and the robot, left there, lost it again (the failure the link map
      exists to prevent). A loss after the operator drove on is the operator's, not a relapse.
    - ``regained_by`` (None if the vehicle never regained its owner's link after the loss): "return" when the
      contact that regained it began while a service block held the lease, or the link was good where the chain
      left the robot (delivery at rest >= GOOD_LINK_QUALITY: the vehicle's own link estimate may take a moment
      to believe it, while the operator already claims and drives), or began before anyone moved the robot
      more than REGAIN_MOVED_M from there; "operator" when it began only after an operator claim had moved the
      robot out of a place where the link was still poor.
    - ``collisions_during_return``: collisions while a service block held the lease.
    - ``return_speed_mps``: distance driven under service blocks over the time they commanded motion.
    - ``blocks``: one record per service block (true frame).
    """
    loss = None
    if run.losses and run.losses[0][1] is not None:
        loss = run.true_at(run.losses[0][1])
    rest, quality, regained_by = _rest_and_regain(run)
    driving = sum(b.driving_s for b in run.blocks)
    blocks = [{"index": b.index, "command": b.command, "start_s": rounded(b.started), "end_s": rounded(b.ended),
               "reason": b.reason or None, "distance_m": rounded(b.distance, 2),
               "displacement_m": rounded(b.max_disp, 2), "limit_m": rounded(b.max_disp_allowed, 2)}
              for b in run.blocks]
    return {
        "loss_position": point(loss), "rest_position": point(rest),
        "rest_link_quality": rounded(quality),
        "link_cycles": sum(1 for e in run.lease_log if e.reason.name == "COMMS_LOST"),
        "regained_by": regained_by, "collisions_during_return": sum(b.collisions for b in run.blocks),
        "return_speed_mps": rounded(sum(b.distance for b in run.blocks) / driving if driving > 0 else None),
        "blocks": blocks,
    }


def _rest_and_regain(run) -> tuple:
    """(rest position, link quality there, regained_by) of the first loss's chain (see ``after_loss``); all None
    without a loss or a trace."""
    tr = run.trace
    if not (run.losses and tr.t):
        return None, None, None
    end_t, end_k = _first_chain_end(run)
    k_rest = len(tr.t) - 1
    if end_k is not None:
        k_rest = next((k - 1 for k in range(end_k, len(tr.t)) if tr.state[k] == State.TELEOP), k_rest)
    rest, quality = tr.true[k_rest], tr.link[k_rest]
    t_loss = run.losses[0][0]
    # the contact that brought the link back began at ``since`` (LINK_REGAINED is declared LNK_REGAIN_S later)
    back = next(((t, since) for t, since in run.link_backs if t >= t_loss - 1e-9), None)
    if back is None:
        return rest, quality, None
    since = back[1] if back[1] is not None else back[0]
    if end_t is None or since <= end_t + 1e-9 or quality >= GOOD_LINK_QUALITY:
        return rest, quality, "return"
    k_back = min(len(tr.t) - 1, max(0, int(round(since / DT)) - 1))
    moved = max((math.dist(tr.true[k], rest) for k in range(end_k, k_back + 1)), default=0.0)
    return rest, quality, "operator" if moved > REGAIN_MOVED_M else "return"


def relapses(events, states) -> int:
    """Losses of the link that follow its regain with no operator teleop in between (see ``compute``)."""
    n, regained = 0, None
    for e in events:
        if e.reason.name == "LINK_REGAINED":
            regained = e.t
        elif e.reason.name == "COMMS_LOST" and regained is not None:
            k0, k1 = int(round(regained / DT)), min(len(states), int(round(e.t / DT)))
            if not any(states[k] == State.TELEOP for k in range(k0, k1)):
                n += 1
            regained = None
    return n


def _holder_is_service(e) -> bool:
    return e.holder.name == "RETURN_SERVICE"


# The scenario's criteria as rules, in the order their failures are said. Each answers the failures it finds, in
# words; a rule marked as needing leases judges returnlink's own machinery (the stale-command guard, its return
# target, the displacement limit of a lease, the commands it rejects, the chain of return blocks), which a plant
# without it (the ArduPilot firmware alone) does not have: for that plant the rule is not judged, rather than
# failed on a figure that is null by nature.
def _stale(c, m, run) -> list[str]:
    n = m["stale_commands_executed"]
    return [f"{n} stale commands executed"] if n else []


def _return_started(c, m, run) -> list[str]:
    if c.return_started is None or (m["return_started_s"] is not None) == c.return_started:
        return []
    return ["no return started" if c.return_started else "a return started"]


def _link_regained(c, m, run) -> list[str]:
    if c.link_regained is None or (m["link_regained_s"] is not None) == c.link_regained:
        return []
    return ["link never regained after the loss" if c.link_regained else "link regained"]


def _target_error(c, m, run) -> list[str]:
    err, limit = m["final_target_error_m"], c.max_final_target_error_m
    return [f"final target error {err} m > {limit} m"] if limit is not None and err is not None and err > limit else []


def _no_target(c, m, run) -> list[str]:
    if c.max_final_target_error_m is not None and m["final_target_error_m"] is None and c.return_started:
        return ["no return target to measure against"]
    return []


def _collisions(c, m, run) -> list[str]:
    return [f"{m['collisions']} collisions > {c.max_collisions}"] if m["collisions"] > c.max_collisions else []


def _displacement(c, m, run) -> list[str]:
    if not c.max_displacement_respected:
        return []
    return [f"lease {b.index}: displacement {b.max_disp:.2f} m > limit {b.max_disp_allowed:.2f} m"
            for b in run.blocks if b.max_disp > b.max_disp_allowed + DISPLACEMENT_SLACK]


def _distance_back(c, m, run) -> list[str]:
    if c.min_distance_back_m is not None and m["distance_back_m"] < c.min_distance_back_m:
        return [f"distance back {m['distance_back_m']} m < {c.min_distance_back_m} m"]
    return []


def _rejected(c, m, run) -> list[str]:
    n = m["commands_rejected"]
    return [f"{n} commands rejected < {c.min_commands_rejected}"] if n < c.min_commands_rejected else []


def _regained_by(c, m, run) -> list[str]:
    if c.regained_by is not None and m["regained_by"] != c.regained_by:
        return [f"link regained by {m['regained_by']}, expected by {c.regained_by}"]
    return []


def _chain(c, m, run) -> list[str]:
    got = [b.reason for b in run.blocks]
    if c.chain_reasons and got[:len(c.chain_reasons)] != list(c.chain_reasons):
        return [f"return blocks ended {got}, expected {list(c.chain_reasons)}"]
    return []


# (rule, needs returnlink's leases)
RULES = ((_stale, True), (_return_started, False), (_link_regained, False), (_target_error, False),
         (_no_target, True), (_collisions, False), (_displacement, True), (_distance_back, False),
         (_rejected, True), (_regained_by, False), (_chain, True))


def verdict(run, m: dict, leases: bool = True) -> list[str]:
    """The scenario's own success criteria (``RULES``), each failure said in words; ``leases`` False: the plant
    flies no lease machinery, and the rules about it are not judged."""
    c = run.scenario.criteria
    return [failure for rule, needs_leases in RULES if leases or not needs_leases for failure in rule(c, m, run)]
