"""The folders show the block diagram: no module imports from a higher layer.

Layers, lowest first: the foundation modules (parameters, claims, analysis,
recordings), plants, estimators and controllers (side by side), loops,
scenes and exercises, and the app above all."""

import ast
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
FOUNDATION = {"parameters", "claims", "analysis", "recordings"}
#: What each part of the lab may import from the lab (besides itself).
ALLOWED = {
    "foundation": {"foundation"},
    "plants": {"foundation"},
    "estimators": {"foundation", "plants"},
    "controllers": {"foundation", "plants"},
    "loops": {"foundation", "plants", "estimators", "controllers"},
    "scenes": {"foundation", "plants", "estimators", "controllers", "loops"},
    "exercises": {"foundation", "plants", "estimators", "controllers", "loops", "scenes"},
    "app": {"foundation", "plants", "estimators", "controllers", "loops", "scenes", "exercises"},
}


def part_of(module: str) -> str:
    """The layer of a dotted module name inside the project."""
    parts = module.split(".")
    if parts[0] == "app":
        return "app"
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
    for package in ("plants", "estimators", "controllers", "loops", "scenes", "exercises"):
        init = ROOT / "lab_modules" / package / "__init__.py"
        doc = ast.get_docstring(ast.parse(init.read_text()))
        assert doc and len(doc) > 40, package


def test_the_checker_sees_a_violation(tmp_path):
    """The layer test can fail: a plant importing a loop is reported."""
    assert part_of("lab_modules.loops.radial_axis_loop") not in ALLOWED["plants"]
    assert part_of("lab_modules.analysis") in ALLOWED["plants"]


# -- exercises stand alone ------------------------------------------------------------------
EXERCISES = ROOT / "lab_modules" / "exercises"
#: Exercise modules: every file of the package but its ``__init__`` and the helpers (``_name.py``).
EXERCISE_MODULES = {path.stem for path in EXERCISES.glob("*.py") if not path.stem.startswith("_")}


def exercises_imported(path: pathlib.Path, source: str | None = None) -> set[str]:
    """The exercise modules other than its own that the module at ``path`` imports, at any depth
    (an imported name ``lab_modules.exercises.X`` counts when X is an exercise module: the
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
