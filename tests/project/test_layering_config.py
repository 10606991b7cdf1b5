"""Every module of the package sits in the layering contract, so none escapes the check.

import-linter only checks the modules a contract names: a new top-level module left out of
the layers would be free to import anything. This test names the ones missing.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "src" / "aiortu"


def _top_level_modules() -> set[str]:
    names = set()
    for path in PACKAGE.iterdir():
        if path.name.startswith("_"):
            continue
        if path.suffix == ".py":
            names.add(f"aiortu.{path.stem}")
        elif path.is_dir() and (path / "__init__.py").exists():
            names.add(f"aiortu.{path.name}")
    return names


def _contracts() -> list[dict[str, object]]:
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    contracts: list[dict[str, object]] = config["tool"]["importlinter"]["contracts"]
    return contracts


def test_every_module_is_in_a_layer() -> None:
    (layers,) = [
        contract["layers"]
        for contract in _contracts()
        if contract["type"] == "layers" and "containers" not in contract
    ]
    assert isinstance(layers, list)
    layered = {name.strip() for layer in layers for name in layer.replace(":", "|").split("|")}
    assert _top_level_modules() - layered == set()


def test_the_core_may_import_no_other_module_of_the_package() -> None:
    (forbidden,) = [
        contract["forbidden_modules"]
        for contract in _contracts()
        if contract.get("source_modules") == ["aiortu.core"]
    ]
    assert isinstance(forbidden, list)
    assert _top_level_modules() - {"aiortu.core"} <= set(forbidden)
