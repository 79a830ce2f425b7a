"""The port's three faces (docs/architecture.md §2 "Ports, not a hub"; issue 39): the command authority, the status
snapshot and the event queue are separate Protocols, each small, and the vehicle provides every member of each with
the very signature the face declares."""

from __future__ import annotations

import ast
import inspect
from pathlib import Path

import numpy as np

from sim.driver import SimDriver
from sim.scenario import load
from vehicle.app import Vehicle
from vehicle.lease import Verdict
from vehicle.params import load_defaults
from vehicle.port import CommandAuthority, EventQueue, Snapshot, VehiclePort

FACES = (CommandAuthority, Snapshot, EventQueue)
MAX_MEMBERS = 12
OWNER, PLAIN = 255, 245
ROOT = Path(__file__).resolve().parents[1]


def members(face: type) -> set[str]:
    """The public members a Protocol declares itself (its methods and properties; not those it inherits)."""
    return {name for name, value in vars(face).items()
            if not name.startswith("_") and (callable(value) or isinstance(value, property))}


def vehicle() -> Vehicle:
    sc = load("open")
    return Vehicle(SimDriver(sc, "rover", np.random.default_rng(1)), load_defaults(), sc.start, 0.0, seed=1)


def test_each_face_has_at_most_twelve_public_members_and_no_two_share_one():
    sizes = {face.__name__: len(members(face)) for face in FACES}
    assert all(0 < n <= MAX_MEMBERS for n in sizes.values()), sizes
    names = [name for face in FACES for name in members(face)]
    assert len(names) == len(set(names))


def test_the_whole_port_is_the_three_faces_and_adds_nothing():
    assert members(VehiclePort) == set()
    assert all(face in VehiclePort.__mro__ for face in FACES)


def test_the_vehicle_provides_every_member_of_every_face_as_declared():
    v = vehicle()
    for face in FACES:
        for name in members(face):
            declared = vars(face)[name]
            assert hasattr(v, name), f"{face.__name__}.{name}"
            if isinstance(declared, property):
                continue  # (a value: the parameter table is the vehicle's own)
            provided = getattr(Vehicle, name)
            assert list(inspect.signature(provided).parameters) == list(inspect.signature(declared).parameters), \
                f"{face.__name__}.{name}"


def test_the_verdict_says_what_autogrant_would_do_without_doing_it():
    v = vehicle()
    assert v.verdict(PLAIN).verdict is not Verdict.EXECUTE  # nobody owns it: no lease to act under
    chk = v.verdict(PLAIN, 190, 0.0)  # as after LEASE_AUTOGRANT: the plain client would act under [E,0]
    assert chk.verdict is Verdict.EXECUTE and chk.lease is not None
    assert v.book.owner is None and v.commands_rejected == 0  # nothing granted, nothing counted
    v.bind_key()  # with a signing key, LEASE_AUTOGRANT does nothing, and the verdict says so
    assert v.verdict(PLAIN, 190, 0.0).verdict is not Verdict.EXECUTE


def test_operator_control_takes_and_gives_up_the_root():
    v = vehicle()
    assert v.operator_control(OWNER, 190, 0.0, True, allow_takeover=False).executes and v.book.owner == OWNER
    assert not v.operator_control(PLAIN, 190, 0.1, False, allow_takeover=False).executes  # not the owner's to give
    assert v.operator_control(OWNER, 190, 0.2, False, allow_takeover=False).executes and v.book.owner is None


def test_the_log_keeps_every_transition_after_the_queue_is_drained():
    v = vehicle()
    v.operator_control(OWNER, 190, 0.0, True, allow_takeover=False)
    drained = v.drain().events
    assert drained and v.drain().events == ()
    assert v.log() == drained and v.log(len(drained)) == ()
    v.rtl(OWNER, 190, 0.5)
    assert [e.reason.name for e in v.log(len(drained))] == ["OPERATOR_EXPIRE"]


def test_the_snapshot_shows_a_teleop_setpoint_and_a_refusal_made_between_two_ticks():
    v = vehicle()
    v.operator_control(OWNER, 190, 0.0, True, allow_takeover=False)
    v.command(OWNER, 190, 0.0, ("arm", True))
    before = v.status()
    v.command(OWNER, 190, 0.0, ("teleop", 0.5, 0.0))
    s = v.status()
    assert before.setpoint is None and s.setpoint is not None and s.setpoint.sender == OWNER
    v.refused()
    assert v.status().commands_rejected == s.commands_rejected + 1


# ----- no part writes its owner's fields ------------------------------------------------------------------------
PARTS = ("vehicle/control.py", "vehicle/contingency.py")  # what a Vehicle is made of, each holding it as ``vehicle``
MUTATORS = {"append", "extend", "clear", "pop", "remove", "insert", "update", "add", "discard", "popleft"}


def _owner(node) -> bool:
    """``v``, ``vehicle`` or ``self.vehicle``: the vehicle a part holds."""
    if isinstance(node, ast.Name):
        return node.id in ("v", "vehicle")
    return isinstance(node, ast.Attribute) and node.attr == "vehicle" and isinstance(node.value, ast.Name) \
        and node.value.id == "self"


def owner_writes(source: str) -> list[str]:
    """Assignments to a field of the part's vehicle, and calls that change one in place (``v.notices.append``)."""
    found = []
    for node in ast.walk(ast.parse(source)):
        targets = node.targets if isinstance(node, ast.Assign) else [node.target] \
            if isinstance(node, (ast.AugAssign, ast.AnnAssign)) else []
        found += [f"line {node.lineno}: {ast.unparse(t)} =" for t in targets
                  if isinstance(t, ast.Attribute) and _owner(t.value)]
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr in MUTATORS:
            held = node.func.value
            if isinstance(held, ast.Attribute) and _owner(held.value):
                found.append(f"line {node.lineno}: {ast.unparse(node)}")
    return found


def test_no_part_of_the_vehicle_writes_its_owners_fields():
    """issue 39: the tick and the return driver read the vehicle and ask it to change (``apply``,
    ``drop_setpoint``, ``announce``); the vehicle keeps its own clock. None of them sets a field of it."""
    found = {path: hits for path in PARTS
             if (hits := owner_writes((ROOT / path).read_text(encoding="utf-8")))}
    assert found == {}


def test_the_owner_write_check_finds_one():
    source = ("def tick(self, t):\n    v = self.vehicle\n    v.t = t\n    self.vehicle.setpoint = None\n"
              "    v.notices.append('x')\n    v.apply(out)\n    self.readings = r\n    v.count += 1\n")
    assert owner_writes(source) == ["line 3: v.t =", "line 4: self.vehicle.setpoint =",
                                    "line 8: v.count =", "line 5: v.notices.append('x')"]


# ----- the simulator's record reads the vehicle as an observer ------------------------------------------------------
# what the record, the metrics, the verdict and the plants may not reach into: the core's own parts and fields (the
# port's reads are status(), params, crumbs(), trail_points(), log() ...)
CORE_FIELDS = {"control", "returns", "trail", "estimator", "linkmap", "event_log", "events", "notices", "book",
               "setpoint", "commands_rejected", "armed", "holding", "contingency", "driver", "state", "t"}
OBSERVERS = ("sim/runner.py", "sim/lease_record.py", "sim/metrics.py", "sim/plants")


def core_reads(source: str) -> list[str]:
    """Reads of a core field through a vehicle (``v.book``, ``run.vehicle.trail``, ``self.vehicle.estimator``), by
    line."""
    found: list[tuple[int, str]] = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Attribute) and node.attr in CORE_FIELDS:
            held = node.value
            if (isinstance(held, ast.Name) and held.id in ("v", "vehicle")) or \
                    (isinstance(held, ast.Attribute) and held.attr == "vehicle"):
                found.append((node.lineno, f"line {node.lineno}: {ast.unparse(node)}"))
    return [text for _, text in sorted(found)]


def test_the_simulators_record_metrics_and_plants_read_only_the_snapshot_and_the_events():
    """issue 39: the run's trace and audit, the lease record, the §7 figures and verdict, and the plants read a
    returnlink vehicle through its port: the status snapshot and the event queue's log."""
    paths = [p for name in OBSERVERS for p in sorted((ROOT / name).rglob("*.py") if (ROOT / name).is_dir()
                                                     else [ROOT / name])]
    found = {str(p.relative_to(ROOT)): hits for p in paths if (hits := core_reads(p.read_text(encoding="utf-8")))}
    assert len(paths) > 5 and found == {}


def test_the_core_read_check_finds_one():
    source = "s = v.status()\nx = v.control.command_out\nlog = run.vehicle.event_log\np = self.vehicle.estimator\n"
    assert core_reads(source) == ["line 2: v.control", "line 3: run.vehicle.event_log",
                                  "line 4: self.vehicle.estimator"]
