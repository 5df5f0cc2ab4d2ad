"""The folders show the block diagram: no module imports from a higher layer, and
nothing imports in a circle.

Layers, lowest first: the foundation modules (parameters, formatting, claims,
analysis, loop_responses, loop_sensitivity, recordings, memo), plants, estimators
and controllers (side by side), loops, scenes and exercises, evaluation; then the app: infra, panels, tab and commands
(side by side), and the roots (cli, server, hall).  Imports inside functions count."""

import ast
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
FOUNDATION = {"parameters", "formatting", "claims", "analysis", "loop_responses", "loop_sensitivity", "recordings",
              "memo"}
#: What each part of the lab may import from the lab (besides itself).
ALLOWED = {
    "foundation": {"foundation"},
    "plants": {"foundation"},
    "estimators": {"foundation", "plants"},
    "controllers": {"foundation", "plants"},
    "loops": {"foundation", "plants", "estimators", "controllers"},
    "scenes": {"foundation", "plants", "estimators", "controllers", "loops"},
    "exercises": {"foundation", "plants", "estimators", "controllers", "loops", "scenes"},
    "evaluation": {"foundation", "plants", "estimators", "controllers", "loops", "scenes", "exercises"},
}
LAB = set(ALLOWED)
ALLOWED |= {
    "app.infra": LAB,
    "app.panels": LAB | {"app.infra"},
    "app.tab": LAB | {"app.infra", "app.panels"},
    "app.commands": LAB | {"app.infra", "app.panels"},
    "app.roots": LAB | {"app.infra", "app.panels", "app.tab", "app.commands"},
}
APP_PACKAGES = ("infra", "panels", "tab", "commands")


def part_of(module: str) -> str:
    """The layer of a dotted module name inside the project."""
    parts = module.split(".")
    if parts[0] == "app":
        return f"app.{parts[1]}" if len(parts) > 1 and parts[1] in APP_PACKAGES else "app.roots"
    assert parts[0] == "lab_modules", module
    if len(parts) == 1:
        return "foundation"
    return "foundation" if parts[1] in FOUNDATION else parts[1]


def project_imports(path: pathlib.Path, source: str | None = None):
    """Dotted names of every project module that ``path`` imports (relative imports resolved),
    function-local imports included; ``source`` stands in for the file's text."""
    package = list(path.relative_to(ROOT).with_suffix("").parts)[:-1]
    for node in ast.walk(ast.parse(path.read_text() if source is None else source)):
        if isinstance(node, ast.ImportFrom):
            base = package[: len(package) - node.level + 1] if node.level else []
            module = ".".join(base + ([node.module] if node.module else []))
            names = [module] + [f"{module}.{a.name}" for a in node.names]
        elif isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        else:
            continue
        for name in names:
            if name.split(".")[0] in ("lab_modules", "app"):
                yield name


SOURCES = sorted([*ROOT.joinpath("lab_modules").rglob("*.py"), *ROOT.joinpath("app").rglob("*.py")])


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: str(p.relative_to(ROOT)))
def test_no_import_from_a_higher_layer(path):
    own = part_of(".".join(path.relative_to(ROOT).with_suffix("").parts))
    for name in project_imports(path):
        target = part_of(name)
        # "lab_modules.exercises.Chart" names a package attribute: the package's layer counts
        assert target == own or target in ALLOWED[own], f"{own} imports {name} ({target})"


def test_every_role_package_is_described():
    packages = [ROOT / "lab_modules" / p for p in ("plants", "estimators", "controllers", "loops", "scenes",
                                                   "exercises", "evaluation")]
    for package in [*packages, *(ROOT / "app" / p for p in APP_PACKAGES)]:
        doc = ast.get_docstring(ast.parse((package / "__init__.py").read_text()))
        assert doc and len(doc) > 40, package


def module_name(path: pathlib.Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def import_graph() -> dict[str, set[str]]:
    """Module -> the project modules it imports (anywhere in the file, functions included);
    ``from package import name`` counts as importing the submodule where ``name`` is one."""
    modules = {module_name(path): path for path in SOURCES}
    graph = {}
    for name, path in modules.items():
        targets = set()
        for imported in project_imports(path):
            while imported and imported not in modules:      # an attribute: its module
                imported = imported.rpartition(".")[0]
            if imported and imported != name:
                targets.add(imported)
        graph[name] = targets
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on_stack, found, counter = {}, {}, [], set(), [], [0]

    def visit(node):
        index[node] = low[node] = counter[0]
        counter[0] += 1
        stack.append(node)
        on_stack.add(node)
        for target in graph.get(node, ()):
            if target not in index:
                visit(target)
                low[node] = min(low[node], low[target])
            elif target in on_stack:
                low[node] = min(low[node], index[target])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return found


def test_no_import_cycle():
    assert cycles(import_graph()) == []


def test_the_cycle_finder_sees_a_cycle():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_the_checker_sees_a_violation(tmp_path):
    """The layer test can fail: a plant importing a loop is reported."""
    assert part_of("lab_modules.loops.radial_axis_loop") not in ALLOWED["plants"]
    assert part_of("lab_modules.analysis") in ALLOWED["plants"]
    assert part_of("app.tab.session") not in ALLOWED["app.commands"]
    assert part_of("app.cli") not in ALLOWED["app.panels"]


# -- exercises stand alone ------------------------------------------------------------------
EXERCISES = ROOT / "lab_modules" / "exercises"
#: Exercise modules: every file of the package but its ``__init__`` and the helpers (``_name.py``).
EXERCISE_MODULES = {path.stem for path in EXERCISES.glob("*.py") if not path.stem.startswith("_")}


def exercises_imported(path: pathlib.Path, source: str | None = None) -> set[str]:
    """The exercise modules other than its own that the module at ``path`` imports, at any depth
    (an imported name ``lab_modules.exercises.<name>`` counts when it is an exercise module: the
    package's own names such as ``Chart`` and the helpers do not)."""
    found = set()
    for name in project_imports(path, source):
        parts = name.split(".")
        if parts[:2] == ["lab_modules", "exercises"] and len(parts) > 2 and parts[2] in EXERCISE_MODULES:
            found.add(parts[2])
    return found - {path.stem}


@pytest.mark.parametrize("path", sorted(p for p in EXERCISES.glob("*.py") if p.stem != "__init__"),
                         ids=lambda p: p.name)
def test_no_exercise_imports_another(path):
    """Changing one exercise's defaults or helpers never changes another: what several share
    lives in a helper module (``_name.py``) or in a lower layer."""
    assert not exercises_imported(path), f"{path.name} imports {sorted(exercises_imported(path))}"


def test_the_exercise_checker_sees_an_import_inside_a_function():
    inside = "def f():\n    from lab_modules.exercises.kalman_noise import setup\n"
    relative = "from .ekf_parameters import linear_axis\n"
    package = "from lab_modules.exercises import Chart, _common, kalman_noise\n"
    helper = EXERCISES / "_common.py"
    assert exercises_imported(EXERCISES / "lqg_vs_pid.py", inside) == {"kalman_noise"}
    assert exercises_imported(EXERCISES / "ekf_disturbance.py", relative) == {"ekf_parameters"}
    assert exercises_imported(EXERCISES / "lqg_vs_pid.py", package) == {"kalman_noise"}
    assert exercises_imported(helper, package) == {"kalman_noise"}
    assert exercises_imported(EXERCISES / "kalman_noise.py", package) == set()
