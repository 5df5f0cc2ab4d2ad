"""The named bundles the compiled kernels take (``typing.NamedTuple`` classes in ``lab_modules``).

numba names compiled code after a bundle's class name and field types, not after its module: two
bundle classes of one name and the same field types in two modules made the kernels share compiled
code they should not (the thrust lift-off kernel ran at half speed once the EKF loop, with a bundle
of the same name, had been loaded first).  So every bundle's class name is unique, and every field
says what it holds (with its unit) in a comment on its line.
"""

from __future__ import annotations

import ast
import pathlib

ROOT = pathlib.Path(__file__).resolve().parents[1] / "lab_modules"


def _bundles() -> list[tuple[pathlib.Path, ast.ClassDef]]:
    found = []
    for path in sorted(ROOT.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ClassDef) and any(
                    isinstance(base, ast.Name) and base.id == "NamedTuple" for base in node.bases):
                found.append((path, node))
    return found


def test_the_kernels_take_bundles():
    assert len(_bundles()) >= 10


def test_every_bundle_has_a_name_of_its_own():
    names = [node.name for _, node in _bundles()]
    assert len(names) == len(set(names)), sorted(name for name in names if names.count(name) > 1)


def test_every_field_is_described_on_its_line():
    missing = []
    for path, node in _bundles():
        lines = path.read_text().splitlines()
        for field in node.body:
            if isinstance(field, ast.AnnAssign) and "#" not in lines[field.lineno - 1]:
                missing.append(f"{path.name}: {node.name}.{field.target.id}")
    assert not missing, missing
