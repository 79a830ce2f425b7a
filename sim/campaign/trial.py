"""One trial: a scenario's content, a robot, a seed, parameter values and a link-loss policy, run to a row.

The trial id is a hash of exactly those inputs (the scenario's text, not its file name), so a trial means the same
thing on every machine, a renamed scenario file keeps its results, and an edited one gets new ids. ``run_trial`` is
the function the workers call: no plots, no files, never raises: whatever goes wrong inside the simulation becomes
a row with status ``error`` and the error text, because one broken trial must not end a campaign.
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import dataclass, field, replace

from sim import registry
from sim.registry import DEFAULT_POLICY


@dataclass(frozen=True)
class Trial:
    """The inputs of one trial. ``scenario`` is the scenario's own name, ``source`` what the spec said (a
    built-in name or a path): both only for people; the id covers ``scenario_text`` instead."""

    scenario: str
    source: str
    scenario_text: str
    vehicle: str
    seed: int
    params: tuple[tuple[str, float], ...] = ()
    policy: str = DEFAULT_POLICY
    # the firmware binary for vehicle ardurover (the PX4 directory for px4rover): where it lives on this machine, not
    # what the trial is, so it is neither hashed nor stored (empty: found again by RETURNLINK_ARDUROVER or PATH, or
    # RETURNLINK_PX4, where the trial runs)
    firmware: str = field(default="", compare=False)

    @property
    def id(self) -> str:
        return trial_id(self.scenario_text, self.vehicle, self.seed, dict(self.params), self.policy)


def trial_id(scenario_text: str, vehicle: str, seed: int, params: dict[str, float], policy: str) -> str:
    """A stable 16-hex-digit hash of a trial's inputs. Parameter values are hashed as floats, so 3 and 3.0 are
    the same trial, and in name order, so the order a spec lists them in does not matter."""
    canon = json.dumps({"scenario": scenario_text, "vehicle": vehicle, "seed": int(seed),
                        "params": {k: float(v) for k, v in sorted(params.items())}, "policy": policy},
                       sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(canon.encode("utf-8")).hexdigest()[:16]


# The radio as a campaign axis: a sweep spec's ``[radio]`` table, carried in a trial's parameters as "radio.NAME".
# name -> (lowest, highest, what it sets); DARPA SubT's virtual radio is exponent 2.5, 40 dB at 1 m, 10 dB spread,
# 20 dBm transmit, -90 dBm noise floor.
RADIO_PREFIX = "radio."
RADIO_AXES: dict[str, tuple[float, float, str]] = {
    "power_dbm": (-40.0, 40.0, "the operator station's transmit power (dBm)"),
    "exponent": (1.5, 6.0, "log-distance path-loss exponent"),
    "shadowing_db": (0.0, 20.0, "log-normal shadowing spread (dB)"),
    "ref_loss_db": (20.0, 80.0, "path loss at 1 m (dB)"),
    "sensitivity_dbm": (-120.0, -50.0, "receiver sensitivity: RSSI of 50 % delivery (dBm)"),
}


def with_radio(sc, settings: dict[str, float]):
    """``sc`` with the radio settings of a trial: the operator station's power, the rest on the radio model."""
    if not settings:
        return sc
    model = {k: v for k, v in settings.items() if k != "power_dbm"}
    sc = replace(sc, radio=replace(sc.radio, **model)) if model else sc
    if "power_dbm" in settings:
        stations = tuple(replace(s, power_dbm=settings["power_dbm"]) if s.name == sc.operator_station else s
                         for s in sc.stations)
        sc = replace(sc, stations=stations)
    return sc


def scenario_of(trial: Trial):
    """The scenario this trial flies: the stored text parsed again, with the trial's parameter values on top of
    the scenario's own and its radio settings on the radio."""
    from sim.scenario import parse

    sc = parse(trial.scenario_text, trial.source)
    if not trial.params:
        return sc
    vehicle = {k: v for k, v in trial.params if not k.startswith(RADIO_PREFIX)}
    radio = {k[len(RADIO_PREFIX):]: v for k, v in trial.params if k.startswith(RADIO_PREFIX)}
    return with_radio(replace(sc, params={**sc.params, **vehicle}), radio)


def simulate(trial: Trial, progress: bool = False):
    """Run the trial's simulation and compute its metrics: the ``Run`` (for plots) with ``run.metrics`` set."""
    from sim import outputs
    from sim.runner import Run

    outside = registry.outside(trial.vehicle)  # the autopilot the vehicle needs, where this machine keeps it
    options = {} if outside is registry.Outside.NONE else {outside.option: outside.locate(trial.firmware or None)}
    run = Run(scenario_of(trial), trial.vehicle, trial.seed, progress=progress, policy=trial.policy,
              **options).run()
    run.metrics = outputs.compute(run)
    return run


def inputs_row(trial: Trial) -> dict:
    return {"trial_id": trial.id, "scenario": trial.scenario, "source": trial.source,
            "scenario_text": trial.scenario_text, "vehicle": trial.vehicle, "seed": trial.seed,
            "params": json.dumps(dict(trial.params), sort_keys=True), "policy": trial.policy}


def error_row(trial: Trial, error: str, cpu_s: float | None = None) -> dict:
    return {**inputs_row(trial), "status": "error", "error": error, "cpu_s": cpu_s}


def run_trial(trial: Trial) -> dict:
    """Inputs in, one row out: the inputs, every metric (§7 keys; missing ones absent), status and error text,
    and the CPU seconds the trial took (for throughput figures, not for results)."""
    c0 = time.process_time()
    try:
        run = simulate(trial)
    except Exception as e:  # noqa: BLE001 - any failure of one trial is that trial's error row
        return error_row(trial, f"{type(e).__name__}: {e}", time.process_time() - c0)
    m = dict(run.metrics)
    row = {**inputs_row(trial), **{k: v for k, v in m.items() if k not in ("scenario", "vehicle", "seed")}}
    row["policy"] = trial.policy
    row["status"] = "ok" if m.get("passed") else "failed"
    row["error"] = None
    row["cpu_s"] = time.process_time() - c0
    return row


def trial_from_row(row: dict) -> Trial:
    """The trial a stored row was made from (the inverse of ``inputs_row``)."""
    params = json.loads(row["params"]) if row.get("params") else {}
    return Trial(row["scenario"], row["source"], row["scenario_text"], row["vehicle"], int(row["seed"]),
                 tuple(sorted((k, float(v)) for k, v in params.items())), row["policy"])
