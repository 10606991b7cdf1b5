"""A private module is private to its package: no other package imports it.

Each package (`aiortu.line`, `aiortu.master`, ...) exports what others may use from its
`__init__`; its `_modules` are its own business. The tests hold to the same where they
can: a name a package exports is imported from the package, not from the module it is
written in (a private name with no public home is still imported from its module).
"""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import grimp


def _owner_of_private(module: str) -> str | None:
    """The package whose private module `module` is, or None for a public module."""
    parts = module.split(".")
    for index, part in enumerate(parts):
        if part.startswith("_") and not part.startswith("__"):
            return ".".join(parts[:index])
    return None


def test_no_package_imports_another_packages_private_modules() -> None:
    graph = grimp.build_graph("aiortu", exclude_type_checking_imports=False)
    crossings = []
    for importer in sorted(graph.modules):
        for imported in sorted(graph.find_modules_directly_imported_by(importer)):
            owner = _owner_of_private(imported)
            if owner is None or owner == "aiortu":  # aiortu._log, aiortu._public: shared
                continue
            if importer != owner and not importer.startswith(owner + "."):
                crossings.append(f"{importer} -> {imported}")
    assert crossings == []


TESTS = Path(__file__).resolve().parents[1]


def _public_twins(module: str, names: list[str]) -> list[str]:
    """The *names* imported from private *module* that its owner package exports as well."""
    owner = _owner_of_private(module)
    if owner is None:
        return []
    package, source = importlib.import_module(owner), importlib.import_module(module)
    exported = getattr(package, "__all__", ())
    return [
        name
        for name in names
        if name in exported and getattr(package, name) is getattr(source, name, None)
    ]


def test_tests_import_public_names_from_their_public_home() -> None:
    offenders = []
    for path in sorted(TESTS.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, ast.ImportFrom) or not (node.module or "").startswith("aiortu"):
                continue
            assert node.module is not None
            twins = _public_twins(node.module, [alias.name for alias in node.names])
            offenders += [f"{path.relative_to(TESTS)}: {node.module}.{name}" for name in twins]
    assert offenders == []


def test_the_check_sees_a_private_import_of_a_public_name() -> None:
    assert _public_twins("aiortu.master._client", ["Master"]) == ["Master"]
    assert _public_twins("aiortu.master", ["Master"]) == []
