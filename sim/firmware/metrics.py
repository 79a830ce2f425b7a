"""The §7 figures of a run of the firmware alone (``sim.plants.firmware.FirmwarePlant.figures``), in the same true
frame as the native runs, plus ``firmware`` (its version) and ``firmware_modes`` (its mode timeline as ArduPilot
names the modes); ``sim.metrics.compute`` adds the run's own keys and the one verdict, as for every plant.

PX4 alone (``sim.plants.px4.PX4Plant``) is read the same way, with its own meaning of the modes, which a plant
states in ``mode_names``, ``return_modes``, ``driving_mode`` and ``home_modes`` (absent: ArduPilot's): its Hold
(AUTO_LOITER) and Return (AUTO_RTL) are the return modes, Offboard the operator's, Return the one with home as its
target.

The firmware has no leases, so its link-loss story is read from its modes: a *return episode* begins when it
switches itself into HOLD, RTL or SMART_RTL (its GCS failsafe; a mode the scripted operator asked for is an
operator RTL, not a failsafe) and ends when the operator takes control again (GUIDED) or the run ends. From there
every key means what it means for the native vehicle:

- ``link_lost_s``: when the firmware last heard its ground station before the first episode; ``reaction_latency_s``
  the episode's start minus that minus LNK_TIMEOUT (the firmware's FS_GCS_TIMEOUT is set to it, at least 2 s).
- ``link_regained_s``: LNK_REGAIN_S into the first run of contact after the loss in which the station's frames
  reached the firmware no more than LNK_GOOD_S apart (the native vehicle's definition of contact).
- ``rest_position``: where the first episode left the robot; ``distance_back_m`` / ``max_displacement_m`` what it
  drove during its episodes; ``final_target_error_m`` the distance from rest to the firmware's home (where it armed)
  for RTL and SmartRTL, whose target home is, and none for Hold, which has no target.
- Keys about returnlink's own machinery are null, not invented: ``stale_commands_executed`` (the firmware has no
  lease to check a command against), ``trail_points`` and ``trail_max_deviation_m`` (SmartRTL's path is internal),
  ``lease_events`` is empty. ``commands_rejected`` counts the firmware's COMMAND_ACKs other than ACCEPTED.
"""

from __future__ import annotations

import bisect
import math

from sim.compare import Repeatability
from sim.firmware.lockstep import MODE_NAMES
from sim.firmware.operator import GUIDED, RETURN_MODES, RTL, SMART_RTL
from sim.metrics import FRAMES, KEYS, REGAIN_MOVED_M, point, rounded
from vehicle.link_watch import GOOD_QUALITY as GOOD_LINK_QUALITY

FIRMWARE_KEYS = (*KEYS, "firmware", "firmware_modes")


def meaning(plant) -> tuple[dict[int, str], frozenset[int], int, tuple[int, ...]]:
    """What the modes of ``plant``'s autopilot mean: (names, return modes, the operator's driving mode, the return
    modes whose target is home); ArduPilot's unless the plant says otherwise."""
    return (getattr(plant, "mode_names", MODE_NAMES), getattr(plant, "return_modes", RETURN_MODES),
            getattr(plant, "driving_mode", GUIDED), getattr(plant, "home_modes", (RTL, SMART_RTL)))


def episodes(plant) -> list[tuple[float, float | None, int]]:
    """(start, end or None, mode) of each return the firmware (``plant``) made on its own: a switch into a return
    mode from a driving mode that the operator did not ask for; it ends when the mode is the operator's driving
    mode (GUIDED, PX4's OFFBOARD) again."""
    _names, returns, driving, _home = meaning(plant)
    out: list[tuple[float, float | None, int]] = []
    asked = [t for t, text in plant.operator.log if text == "rtl requested"]
    current: list | None = None
    # a plant whose returns do not show as modes of their own (the applet's, in GUIDED) marks them in its timeline
    timeline = getattr(plant, "return_timeline", None)
    for t, mode in timeline if timeline is not None else plant.link.tap.modes:
        if current is None and mode in returns and t > 0:
            if any(abs(t - a) < 2.0 for a in asked):
                continue
            current = [t, None, mode]
        elif current is not None and mode == driving:
            current[1] = t
            out.append(tuple(current))
            current = None
    if current is not None:
        out.append(tuple(current))
    return out


def contact_runs(heard: list[float], good_s: float) -> list[tuple[float, float]]:
    """Maximal runs (first, last) of the times the firmware heard its station, no two more than ``good_s`` apart."""
    runs: list[tuple[float, float]] = []
    for t in heard:
        if runs and t - runs[-1][1] <= good_s:
            runs[-1] = (runs[-1][0], t)
        else:
            runs.append((t, t))
    return runs


def figures(run) -> dict:
    """The figures of ``run`` (a ``sim.runner.Run`` of the firmware plant) read from the firmware's own record: its
    rows, the times it heard its station, its modes (see the module docstring)."""
    plant = run.plant
    names, _returns, _driving, home_modes = meaning(plant)
    sc, rows, heard = run.scenario, plant.rows, plant.heard
    eps = episodes(plant)
    first = eps[0] if eps else None
    lost = _last_heard_before(heard, first)
    since, regained = _contact_again(heard, first, float(sc.params.get("LNK_GOOD_S", 1.5)),
                                     float(sc.params.get("LNK_REGAIN_S", 1.0)))
    at = _RowAt(rows)
    blocks, distance, max_disp, driving, collided = _episode_blocks(eps, at, names)
    rest, quality, regained_by, final_err = _rest(first, since, at, home_modes)
    return {
        "link_lost_s": rounded(lost), "return_started_s": rounded(first[0] if first else None),
        "reaction_latency_s": rounded(first[0] - lost - plant.lnk_timeout if first and lost is not None else None, 4),
        "link_regained_s": rounded(regained), "distance_back_m": rounded(distance, 2),
        "max_displacement_m": rounded(max_disp, 2),
        "final_target_error_m": rounded(final_err, 2), "collisions": run.world.collisions,
        "stale_commands_executed": None, "commands_rejected": plant.link.tap.rejected,
        "estimator_rmse_m": rounded(_estimator_rmse(rows)), "trail_points": None, "trail_max_deviation_m": None,
        "lease_events": [], "loss_position": point(run.true_at(lost) if lost is not None else None),
        "rest_position": point(rest), "rest_link_quality": rounded(quality), "link_cycles": len(eps),
        "regained_by": regained_by, "collisions_during_return": collided,
        "return_speed_mps": rounded(distance / driving if driving > 0 else None), "blocks": blocks,
        "frames": {**FRAMES, "final_target_error_m": "true (the firmware's home: where the rover armed)"},
        "relapses": None,  # returnlink's own notion (a regain, then a loss with no operator driving): no leases here
        "firmware": plant.link.tap.version, "firmware_modes": plant.firmware_modes,
    }


def _last_heard_before(heard: list[float], first) -> float | None:
    """When the firmware last heard its station before the first episode began (None: no episode, or never)."""
    if first is None:
        return None
    k = bisect.bisect_right(heard, first[0]) - 1
    return heard[k] if k >= 0 else None


def _contact_again(heard: list[float], first, good_s: float, regain_s: float) -> tuple[float | None, float | None]:
    """(since, regained): the start of the first run of contact after the first episode began that lasts
    LNK_REGAIN_S, and LNK_REGAIN_S into it (the native vehicle's definition of a regain); None, None: none."""
    if first is None:
        return None, None
    for a, b in contact_runs(heard, good_s):
        if b >= first[0] and b - max(a, first[0]) >= regain_s - 1e-9:
            since = max(a, first[0])
            return since, since + regain_s
    return None, None


class _RowAt:
    """The firmware's rows indexed by simulated time: one row a tick (50 Hz unless the rows say otherwise)."""

    def __init__(self, rows: list) -> None:
        self.rows = rows
        self.dt = rows[1][0] - rows[0][0] if len(rows) > 1 else 0.02
        self.last = len(rows) - 1

    def k(self, t: float) -> int:
        return min(len(self.rows) - 1, max(0, int(round(t / self.dt)) - 1))


def _episode_blocks(eps, at: _RowAt, names: dict[int, str]):
    """The report's blocks, one per episode (what the firmware drove in it), and over all of them: (blocks,
    distance driven, the largest displacement, time moving, collisions)."""
    rows, dt = at.rows, at.dt
    blocks, distance, max_disp, driving, collided = [], 0.0, 0.0, 0.0, 0
    for i, (a, b, mode) in enumerate(eps):
        ka, kb = at.k(a), at.k(b) if b is not None else at.last
        start = rows[ka][1:3]
        d = disp = moving = 0.0
        for k in range(ka + 1, kb + 1):
            step = math.dist(rows[k][1:3], rows[k - 1][1:3])
            d += step
            moving += dt if step > 1e-4 else 0.0
            disp = max(disp, math.dist(rows[k][1:3], start))
        hits = rows[kb][11] - rows[ka][11]
        distance, max_disp, driving, collided = distance + d, max(max_disp, disp), driving + moving, collided + hits
        blocks.append({"index": i, "command": names.get(mode, str(mode)), "start_s": rounded(a),
                       "end_s": rounded(b), "reason": "OPERATOR" if b is not None else None,
                       "distance_m": rounded(d, 2), "displacement_m": rounded(disp, 2), "limit_m": None})
    return blocks, distance, max_disp, driving, collided


def _rest(first, since: float | None, at: _RowAt, home_modes) -> tuple:
    """Where the first episode left the robot and its link there, who regained the link (the return, or the
    operator who drove more than REGAIN_MOVED_M from rest before it came back), and the distance from rest to home
    for a return whose target is home: (rest, quality, regained_by, final error), all None without an episode."""
    if first is None:
        return None, None, None, None
    rows = at.rows
    k_rest = at.k(first[1]) - 1 if first[1] is not None else at.last
    rest, quality = rows[k_rest][1:3], rows[k_rest][6]
    regained_by = final_err = None
    if since is not None:
        if first[1] is None or since <= first[1] + 1e-9 or quality >= GOOD_LINK_QUALITY:
            regained_by = "return"
        else:
            moved = max((math.dist(rows[k][1:3], rest) for k in range(k_rest, at.k(since) + 1)), default=0.0)
            regained_by = "operator" if moved > REGAIN_MOVED_M else "return"
    armed = next((r for r in rows if r[10]), None)
    if first[2] in home_modes and armed is not None:
        final_err = math.dist(rest, armed[1:3])
    return rest, quality, regained_by, final_err


def _estimator_rmse(rows: list) -> float | None:
    """The firmware's EKF against the truth over the rows where it had an estimate."""
    est = [(r[1], r[2], r[3], r[4]) for r in rows if not math.isnan(r[3])]
    return math.sqrt(sum((a - c) ** 2 + (b - d) ** 2 for a, b, c, d in est) / len(est)) if est else None


# How far two runs of the same trial may differ and still count as the same. A firmware run is repeatable only
# within the firmware's own determinism: ArduPilot SITL runs some work on threads of its own (its IO thread, where
# SmartRTL also simplifies its path), so under a busy CPU a frame can leave it one 20 ms tick later than in another
# run. The radio draws a packet's fate from its send time, so that tick can decide whether, say, the operator's
# last DO_CHANGE_SPEED got through before the link died, and the outcome after the loss can then differ by much
# more than the tick (measured, tunnel, 100 s, three runs in one process: SmartRTL came home at 1.59 m/s twice and
# at 1.04 m/s once, 7 m short of home when the run ended). What stays within this tolerance run to run is the
# drive until the loss; ``sim.compare.differing`` names the metrics beyond it rather than calling two runs equal.
TOLERANCE = {"s": 0.2, "m": 1.0, "count": 2, "mps": 0.1, "quality": 0.15,
             # a mode change the operator asked for and the firmware had not yet shown is asked again a second later
             # (sim/firmware/operator.py RETRY_S): a frame a tick late moves it by that second
             "mode_s": 1.2,
             # the refusals of a stream (a held stick at 10 Hz while a return holds the lease) follow the return's
             # timing: a fifth of a second is two refusals, and the firmware's own jitter moves the return by that
             "refusals": 5}


def _tolerance(key: str, metric: str) -> float:
    """How far figure ``key`` (of metric ``metric``) may move between two runs of one firmware trial."""
    if metric == "firmware_modes" and key == "t":
        return TOLERANCE["mode_s"]
    if key.endswith("_s") or key == "t":
        return TOLERANCE["s"]
    if key.endswith("_mps"):
        return TOLERANCE["mps"]
    if key in ("rest_link_quality", "estimator_rmse_m"):
        return TOLERANCE["quality"]
    if key.endswith("_m") or key.endswith("_position"):
        return TOLERANCE["m"]
    # a crumb is laid every TRL_SPACING of driven path, so a path that differs by the firmware's repeatability
    # (a tenth of a metre in the tunnel) can hold a crumb more or less: the count's tolerance, not an exact match
    if key in ("collisions", "collisions_during_return", "trail_points"):
        return TOLERANCE["count"]
    if key == "commands_rejected":
        return TOLERANCE["refusals"]
    return 0.0


# What a run of a real autopilot repeats (``sim.compare.differing``): each figure within ``TOLERANCE``, the mode
# timeline mode by mode with each switch within ``TOLERANCE["mode_s"]``; the real-time factor and the verdict's
# wording (which quotes counts) are left out
REPEATABILITY = Repeatability(_tolerance, frozenset({"real_time_factor", "failures", "passed"}), exact=False)
