"""The architecture page's module map names every private module of the package, and no
module that is gone: the maintainer's map stays true to the tree."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SOURCE = ROOT / "src" / "aiortu"


def modules_in_the_tree() -> set[str]:
    return {
        path.relative_to(SOURCE).as_posix()
        for path in SOURCE.rglob("_*.py")
        if path.name not in ("__init__.py", "__main__.py")
    }


def modules_on_the_page() -> set[str]:
    page = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    section = page.split("## Module map", 1)[1].split("\n## ", 1)[0]
    return set(re.findall(r"^\| `([\w/]+\.py)` \|", section, flags=re.MULTILINE))


def test_the_module_map_names_every_private_module_and_no_other() -> None:
    tree, page = modules_in_the_tree(), modules_on_the_page()
    assert {"missing from the map": tree - page, "gone from the tree": page - tree} == {
        "missing from the map": set(),
        "gone from the tree": set(),
    }
