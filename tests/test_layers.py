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


def project_imports(path: pathlib.Path):
    """Dotted names of every project module that ``path`` imports (relative imports resolved)."""
    package = list(path.relative_to(ROOT).with_suffix("").parts)[:-1]
    for node in ast.walk(ast.parse(path.read_text())):
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
