"""The printed summary of a run, whichever plant flew it: one layout of the §7 figures (a "-" where the plant has none:
no trail for an autopilot alone), the plant's own lines under the first (``about``: the autopilot and how it booted,
what a companion passed and refused), the lease events where returnlink flew, the autopilot's modes where one
flew, the notes (events that did not apply to the plant), and the verdict."""

from __future__ import annotations

from collections.abc import Sequence


def _f(x, unit: str = "", nd: int = 1) -> str:
    return "-" if x is None else f"{x:.{nd}f}{unit}"


def _n(x) -> str:
    return "-" if x is None else str(x)


def _reaction(latency: float | None) -> str:
    """The reaction as a reader should take it: from the moment the trigger's condition became true (LNK_TIMEOUT
    of silence, or the owner's delivery falling below LNK_MIN_Q; an autopilot's own timeout for its failsafe)."""
    if latency is None:
        return "reaction -"
    return f"reaction {latency:.3f} s after the trigger's condition (LNK_TIMEOUT of silence or LNK_MIN_Q)"


def summary(run, m: dict, about: Sequence[str] = (), modes_title: str = "firmware modes") -> str:
    """The summary of ``run`` and its metrics ``m``; ``about``: the plant's own lines under the first;
    ``modes_title``: what the autopilot's mode timeline (``firmware_modes``, where there is one) is called."""
    cycles = m["link_cycles"]
    lines = [
        f"returnlink sim run {m['scenario']} --vehicle {m['vehicle']} --seed {m['seed']} --policy {m['policy']}",
        *about,
        f"  simulated {_f(m['sim_duration_s'], ' s')} at {_f(m['real_time_factor'], 'x real time')}",
        f"  link lost at {_f(m['link_lost_s'], ' s')}, return began {_f(m['return_started_s'], ' s')}"
        f" ({_reaction(m['reaction_latency_s'])})",
        f"  link regained at {_f(m['link_regained_s'], ' s')}; drove {_f(m['distance_back_m'], ' m')} back,"
        f" max displacement {_f(m['max_displacement_m'], ' m')}, target error {_f(m['final_target_error_m'], ' m', 2)}",
        f"  loss at {m['loss_position']}, at rest at {m['rest_position']}"
        f" (delivery {_f(m['rest_link_quality'], '', 2)}), link regained by {m['regained_by'] or '-'},"
        f" {cycles} link loss{'' if cycles == 1 else 'es'} (true frame)",
        f"  collisions {m['collisions']} ({m['collisions_during_return']} during returns), stale commands executed"
        f" {_n(m['stale_commands_executed'])},"
        f" commands rejected {m['commands_rejected']}",
        f"  estimator RMSE {_f(m['estimator_rmse_m'], ' m', 2)}, trail {_n(m['trail_points'])} points"
        f" (max deviation {_f(m['trail_max_deviation_m'], ' m', 2)})",
    ]
    if m.get("lease_events"):
        lines.append("  lease events:")
        lines += [f"    {e['t']:7.2f} s  {e['expired']} -> {e['current']}  {e['reason']}" for e in m["lease_events"]]
    if "firmware_modes" in m:
        lines.append(f"  {modes_title}:")
        lines += [f"    {e['t']:7.2f} s  {e['mode']}" for e in m["firmware_modes"]]
    lines += [f"  note: {n}" for n in run.notes]
    lines.append("  PASSED" if m["passed"] else "  FAILED: " + "; ".join(m["failures"]))
    return "\n".join(lines)
