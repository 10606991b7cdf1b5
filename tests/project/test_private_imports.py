"""A private module is private to its package: no other package imports it.

Each package (`aiortu.line`, `aiortu.master`, ...) exports what others may use from its
`__init__`; its `_modules` are its own business.
"""

from __future__ import annotations

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
