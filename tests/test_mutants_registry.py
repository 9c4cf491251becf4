"""The registry of named mutants (tools/mutants.py, `make mutants`) stays applicable as the code moves: each mutant's
text occurs exactly once in its file (code moved between modules otherwise leaves a mutant silently unapplied), its
replacement differs, and every test it names exists. Reads files only; running the mutants is `make mutants`."""
from __future__ import annotations

import ast
import importlib.util
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def _registry() -> dict:
    spec = importlib.util.spec_from_file_location("mutants_tool", REPO / "tools" / "mutants.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.MUTANTS


MUTANTS = _registry()


def _test_names(path: Path) -> set:
    """Module-level test functions and Class::method names defined in a test file."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names = set()
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            names.add(node.name)
        elif isinstance(node, ast.ClassDef):
            names |= {f"{node.name}::{f.name}" for f in node.body if isinstance(f, ast.FunctionDef)}
    return names


@pytest.mark.parametrize("name", sorted(MUTANTS))
def test_mutant_applies_once_and_names_existing_tests(name):
    path, old, new, tests = MUTANTS[name]
    source = REPO / path
    assert source.is_file(), f"{name}: {path} does not exist"
    assert source.read_text(encoding="utf-8").count(old) == 1, f"{name}: its text is not found exactly once in {path}"
    assert old != new and tests, name
    for t in tests:
        file, _, test = t.partition("::")
        assert (REPO / file).is_file(), f"{name}: {file} does not exist"
        if test:
            assert test in _test_names(REPO / file), f"{name}: {file} has no test {test}"
