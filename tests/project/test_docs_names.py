"""Every `aiortu...` name the guides show in code exists and is public.

Public means: each module on the way is public (no part starts with an underscore), each
name a module gives is in its `__all__` (or is a public submodule), and an attribute of a
class is one without a leading underscore that the class has. The guides are README.md and
docs/*.md (but for the architecture page); names are taken from their code spans and code
blocks, including `from aiortu... import ...` lines.
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import re
from pathlib import Path
from types import ModuleType

import pytest

import aiortu

ROOT = Path(__file__).resolve().parents[2]
# The architecture page is for the people who work on aiortu: it names the insides.
GUIDES = [
    ROOT / "README.md",
    *sorted(path for path in (ROOT / "docs").glob("*.md") if path.name != "architecture.md"),
]
CODE = re.compile(r"```[^\n]*\n(?P<block>.*?)```|`(?P<span>[^`\n]+)`", re.S)
DOTTED = re.compile(r"(?<![\w./-])aiortu(?:\.[A-Za-z_]\w*)+")
FROM_IMPORT = re.compile(r"^\s*from (aiortu(?:\.\w+)*) import \(?([\w, \n]+?)\)?\s*$", re.M)


def names_in(page: Path) -> set[str]:
    names: set[str] = set()
    for match in CODE.finditer(page.read_text(encoding="utf-8")):
        code = match.group("block") or match.group("span") or ""
        names.update(DOTTED.findall(code))
        for module, imported in FROM_IMPORT.findall(code):
            names.update(f"{module}.{name.strip()}" for name in imported.split(",") if name.strip())
    return names


def why_not_public(dotted: str) -> str | None:
    """None if *dotted* names a public thing, else what is wrong with it."""
    current: object = aiortu
    path = "aiortu"
    for part in dotted.split(".")[1:]:
        if part.startswith("_"):
            return f"{path}.{part} is private"
        if isinstance(current, ModuleType):
            package = hasattr(current, "__path__")
            spec = importlib.util.find_spec(f"{path}.{part}") if package else None
            if spec is not None:
                current = importlib.import_module(f"{path}.{part}")
            elif part in getattr(current, "__all__", ()):
                current = getattr(current, part)
            else:
                return f"{path} does not export {part}"
        elif inspect.isclass(current) and hasattr(current, part):
            current = getattr(current, part)
        else:
            return f"{path} has no public attribute {part}"
        path = f"{path}.{part}"
    return None


@pytest.mark.parametrize("page", GUIDES, ids=lambda page: page.name)
def test_the_aiortu_names_a_guide_shows_are_public(page: Path) -> None:
    problems = {name: why_not_public(name) for name in sorted(names_in(page))}
    assert {name: why for name, why in problems.items() if why} == {}


def test_the_check_finds_names_and_refuses_private_ones() -> None:
    found = names_in(ROOT / "docs" / "master.md")
    assert "aiortu.open_master" in found
    assert "aiortu.UnitOffline" in found  # the guide tells users to catch it
    assert why_not_public("aiortu.UnitOffline") is None
    assert why_not_public("aiortu.core.serial.LineSettings") is None
    assert why_not_public("aiortu.Point.of") is None
    assert why_not_public("aiortu.slave._store.Block") == "aiortu.slave._store is private"
    assert why_not_public("aiortu.master.LineEngine") == "aiortu.master does not export LineEngine"
    assert why_not_public("aiortu.store") == "aiortu does not export store"
