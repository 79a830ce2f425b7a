"""The package boundaries of the layout: the onboard software runs without the simulator, a ground station needs
only the protocol in ``link/``, never the onboard package, and no two modules import each other. And the layout of
the tests: each test file declares its own tier."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path


def _loaded_after_importing(modules: list[str]) -> set[str]:
    code = ("import importlib, sys\n"
            f"for m in {modules!r}: importlib.import_module(m)\n"
            "print('\\n'.join(sorted({n.split('.')[0] for n in sys.modules})))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120)
    return set(out.stdout.split())


def test_the_ground_station_needs_no_onboard_code():
    loaded = _loaded_after_importing(["gcs.station", "gcs.client", "gcs.plans", "gcs.commands", "gcs.shell",
                                      "gcs.cli", "gcs.mapserver", "gcs.track"])
    assert "gcs" in loaded and "link" in loaded
    assert "vehicle" not in loaded and "sim" not in loaded


def test_the_vehicle_runs_without_the_simulator():
    loaded = _loaded_after_importing(["vehicle.app", "vehicle.keystore", "vehicle.epochs",
                                      "vehicle.companion.app", "vehicle.companion.cli"])
    assert "vehicle" in loaded and "sim" not in loaded


# ----- the import graph: no circles ---------------------------------------------------------------------------
ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("vehicle", "link", "gcs", "sim")
# benchmarks/ is no package, but its scripts import the project like any room: their modules join the graph by the
# same dotted names (``benchmarks.sitl_bench``)
ROOMS = (*PACKAGES, "benchmarks")


def _project_modules() -> dict[str, Path]:
    """Every module of the four packages and of benchmarks/ by its dotted name (a package by its own:
    ``vehicle.services``)."""
    modules = {}
    for package in ROOMS:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            modules[".".join(parts)] = path
    return modules


def _imports(module: str, source: str, is_package: bool, modules: dict[str, Path]) -> set[str]:
    """The project modules that ``module`` (its text ``source``) imports, by every import statement in it."""
    here = module.split(".") if is_package else module.split(".")[:-1]
    names: list[str] = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            names += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            parent = node.module or ""
            if node.level:  # relative: from the package this file is in, one level up per further dot
                parent = ".".join(here[:len(here) - (node.level - 1)] + ([node.module] if node.module else []))
            # ``from vehicle import lease`` imports the module vehicle.lease when there is one, else the package
            names += [f"{parent}.{alias.name}" if f"{parent}.{alias.name}" in modules else parent
                      for alias in node.names]
    found = set()
    for name in names:
        while name and name not in modules:  # ``import a.b.c`` where only a.b is a module of ours: a.b
            name = name.rpartition(".")[0]
        if name and name != module:
            found.add(name)
    return found


def _import_graph() -> dict[str, set[str]]:
    modules = _project_modules()
    return {m: _imports(m, path.read_text(encoding="utf-8"), path.name == "__init__.py", modules)
            for m, path in modules.items()}


def _tangles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm), each sorted: the modules
    of one or more circles of imports. A graph without circles has none."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def _circle(graph: dict[str, set[str]], start: str) -> list[str]:
    """A shortest circle of imports from ``start`` back to it (breadth first), e.g. ``[a, b, a]``; [] if none."""
    came_from: dict[str, str] = {}
    frontier = [start]
    while frontier:
        following = []
        for v in frontier:
            for w in sorted(graph[v]):
                if w == start:
                    way = [v]
                    while way[-1] != start:
                        way.append(came_from[way[-1]])
                    return [*reversed(way), start]
                if w not in came_from:
                    came_from[w] = v
                    following.append(w)
        frontier = following
    return []


def test_no_two_modules_import_each_other_type_only_imports_included():
    """docs/architecture.md §2: no circle in the import graph of vehicle/, link/, gcs/ and sim/.

    Every import statement counts, wherever it stands: at the top, under ``if TYPE_CHECKING:``, inside a function,
    a class or a ``try``; ``import x`` and ``from x import y`` alike, relative ones resolved. ``from vehicle import
    lease`` imports the module vehicle.lease when that file exists, else the package vehicle; ``import a.b`` the
    module a.b. Only the project's own modules are nodes. A failure lists each tangle's modules and one circle in it.
    """
    graph = _import_graph()
    assert len(graph) > 100 and graph["vehicle.app"]  # the files were found and read
    assert [(tangle, _circle(graph, tangle[0])) for tangle in _tangles(graph)] == []


# the rooms that talk to the vehicle core through its port (docs/architecture.md §2 "Ports, not a hub")
PORT_ROOMS = ("vehicle.services", "vehicle.companion", "sim.policies")
CORE = "vehicle.app"


def _importing_the_core(graph: dict[str, set[str]]) -> set[str]:
    """The modules of the port rooms (a package and everything under it) that import ``vehicle.app``."""
    return {m for m, found in graph.items()
            if any(m == room or m.startswith(room + ".") for room in PORT_ROOMS) and CORE in found}


def test_the_services_the_companion_and_the_policies_see_the_vehicle_only_through_its_port():
    """docs/architecture.md §2: no module under vehicle/services/, vehicle/companion/ or sim/policies/ imports
    vehicle.app, type-only imports included (the same graph as above); they hold a ``vehicle.port.VehiclePort``."""
    graph = _import_graph()
    assert all(room in graph for room in PORT_ROOMS)  # the rooms were found
    offenders = _importing_the_core(graph)
    assert offenders == set()


def test_the_port_check_finds_an_import_of_the_core_in_a_room():
    graph = {"vehicle.services.x": {"vehicle.app"}, "vehicle.companion": {"vehicle.port"},
             "sim.policies.y": {"vehicle.port"}, "vehicle.servicesx": {"vehicle.app"}, "sim.runner": {"vehicle.app"}}
    assert _importing_the_core(graph) == {"vehicle.services.x"}


# the core's insides: only the onboard package builds on them; every other room boots the core through
# vehicle/core.py (``boot_core``, with ``DT``, ``State`` and the real-time shell ``run``) and reads it through its port
INSIDES = ("vehicle.app", "vehicle.control")
OUTSIDE_ROOMS = ("sim", "gcs", "link", "benchmarks")


def _reaching_inside(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    """The modules of the rooms outside the onboard package that import one of ``INSIDES``, with what they import."""
    return {m: found & set(INSIDES) for m, found in graph.items()
            if m.split(".")[0] in OUTSIDE_ROOMS and found & set(INSIDES)}


def test_no_room_outside_the_vehicle_imports_the_cores_insides():
    """issue 39: nothing in sim/, gcs/, link/ or benchmarks/ imports vehicle.app or vehicle.control, type-only and
    local imports included (the same graph as above): a plant boots the core through ``vehicle.core.boot_core`` and
    reads it through its port, as the companion does.

    The tests are not a room of the layout: a test of the core's own parts (tests/test_app.py, test_authority.py,
    ...) imports them as a white-box test must, and a rig standing for a room outside may build a ``Vehicle`` by
    hand. What binds the tests is the private-names rule below: a test file may import the private names of the
    module it is named after, and no others."""
    graph = _import_graph()
    assert all(any(m.split(".")[0] == room for m in graph) for room in OUTSIDE_ROOMS)  # the rooms were found
    assert _reaching_inside(graph) == {}


def test_the_insides_check_finds_an_import_of_app_or_control_outside():
    graph = {"sim.runner": {"vehicle.app", "vehicle.port"}, "benchmarks.x_bench": {"vehicle.control"},
             "gcs.station": {"link.codec"}, "vehicle.core": {"vehicle.app"}, "simx.y": {"vehicle.app"},
             "link.proxy": {"vehicle.core"}}
    assert _reaching_inside(graph) == {"sim.runner": {"vehicle.app"}, "benchmarks.x_bench": {"vehicle.control"}}


def test_the_import_graph_sees_type_only_local_and_relative_imports_and_finds_circles():
    modules = _project_modules()
    source = ("from typing import TYPE_CHECKING\n"
              "if TYPE_CHECKING:\n    from vehicle.lease import LeaseBook\n"
              "def f():\n    from vehicle import trail\n    import sim.runner\n"
              "from . import returning\nfrom .services import base\nimport numpy\nfrom vehicle import State\n")
    assert _imports("vehicle.app", source, False, modules) == {
        "vehicle.lease", "vehicle.trail", "sim.runner", "vehicle.returning", "vehicle.services.base", "vehicle"}
    graph = {"a": {"b"}, "b": {"c", "e"}, "c": {"a"}, "d": {"a"}, "e": set()}
    assert _tangles(graph) == [["a", "b", "c"]] and _circle(graph, "a") == ["a", "b", "c", "a"]
    assert _tangles({"a": {"b"}, "b": set()}) == [] and _circle({"a": {"b"}, "b": set()}, "a") == []


# ----- the test tiers: declared in each test file -------------------------------------------------------------
def test_conftest_names_no_test_file_and_no_test():
    """A tier is a ``pytestmark`` in the test file or a mark on the test, never a list of names in conftest.py."""
    text = (ROOT / "tests" / "conftest.py").read_text(encoding="utf-8")
    assert re.findall(r"\btest_\w*", text) == []  # (pytest_ hooks are no test names)


def test_every_firmware_test_file_is_marked_firmware():
    """A test file with "firmware" in its name belongs to the firmware tier: its module-level ``pytestmark``
    carries ``pytest.mark.firmware``."""
    files = sorted((ROOT / "tests").glob("test_*firmware*.py"))
    unmarked = []
    for path in files:
        marks = set()
        for node in ast.parse(path.read_text(encoding="utf-8")).body:
            if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "pytestmark" for t in node.targets):
                values = node.value.elts if isinstance(node.value, (ast.List, ast.Tuple)) else [node.value]
                marks |= {ast.unparse(v) for v in values}
        if "pytest.mark.firmware" not in marks:
            unmarked.append(path.name)
    assert files and unmarked == []


def _private_imports(module: str, source: str) -> list[str]:
    """``from M import _name`` of another module of the project: its private name (``__future__`` and dunders
    aside)."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if (isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] in PACKAGES
                and node.module != module):
            found += [f"{module}: from {node.module} import {a.name}" for a in node.names
                      if a.name.startswith("_") and not a.name.startswith("__")]
    return found


def test_no_module_imports_another_modules_private_names():
    """issue 29: a name with a leading underscore is its module's own business; another module that needs it
    needs a public name (the SmartRTL baseline once imported the trail's ``_douglas_peucker``). The benchmarks'
    scripts count as modules here too."""
    found = [f for m, path in _project_modules().items() for f in _private_imports(m, path.read_text(encoding="utf-8"))]
    assert found == []


def _test_subject(path: Path) -> str:
    """The project module a test file is named after: tests/test_standoff.py -> ``standoff`` (matched against
    the last part of a module's name, so vehicle.standoff and sim.standoff would both be its subject)."""
    return path.stem.removeprefix("test_")


def _tests_private_imports(path: Path, source: str) -> list[str]:
    """The private names ``path`` (a file under tests/) imports from a module other than the one it is named after."""
    subject = _test_subject(path)
    return [f for f in _private_imports(f"tests.{path.stem}", source)
            if f.split(" import ")[0].split("from ")[1].rpartition(".")[2] != subject]


def test_a_test_imports_private_names_only_of_the_module_it_is_named_after():
    """issue 39: the tests' own private imports are covered too. A test may reach into the module it tests
    (tests/test_standoff.py imports vehicle.standoff's ``_arcs``), never into another one: what a second module
    needs of it is a public name, for a test as for the code."""
    files = sorted((ROOT / "tests").rglob("*.py"))
    found = [f for path in files for f in _tests_private_imports(path, path.read_text(encoding="utf-8"))]
    assert len(files) > 100 and found == []


def test_the_tests_private_import_check_finds_one():
    source = "from vehicle.standoff import _arcs\nfrom vehicle.trail import _douglas_peucker\n"
    assert _tests_private_imports(ROOT / "tests" / "test_standoff.py", source) == \
        ["tests.test_standoff: from vehicle.trail import _douglas_peucker"]


def test_the_private_import_check_finds_one():
    assert _private_imports("sim.policies.smartrtl", "from vehicle.trail import _douglas_peucker, seg_dist\n") == \
        ["sim.policies.smartrtl: from vehicle.trail import _douglas_peucker"]
    assert _private_imports("vehicle.trail", "from __future__ import annotations\nfrom vehicle import __doc__\n") == []


# ----- modules found by import, never by a string -----------------------------------------------------------
def _string_imports(source: str) -> list[str]:
    """Calls that load a module named by a string (``importlib.import_module(...)``, ``__import__(...)``): the
    import graph above cannot see what they load."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Call):
            f = node.func
            name = f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else ""
            if name in ("import_module", "__import__"):
                found.append(f"line {node.lineno}: {ast.unparse(node)}")
    return found


def test_no_module_is_loaded_from_a_string():
    """issue 39: a plant draws its pictures with a module it imports (``Plant.pictures``), not one named by a
    string that no layout check sees."""
    found = {m: hits for m, path in _project_modules().items()
             if (hits := _string_imports(path.read_text(encoding="utf-8")))}
    assert found == {}


def test_the_string_import_check_finds_one():
    assert _string_imports("import importlib\nreport = importlib.import_module(plant.report)\n") == \
        ["line 2: importlib.import_module(plant.report)"]
    assert _string_imports("m = __import__('sim.report')\n") == ["line 1: __import__('sim.report')"]
    assert _string_imports("from sim import report\n") == []
