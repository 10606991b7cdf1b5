"""The site builds with --strict, and the API reference shows public names, rendered.

`mkdocs build --strict` fails on any warning, and mkdocs-autorefs reports every
cross-reference it cannot resolve as one, so a docstring that names something the
reference does not show breaks the build (not with `--quiet`, which hides those warnings
from the count as well as from the screen). The pages of the API reference are then read
as a person sees them (the text of the HTML, tags removed): no Sphinx role left raw, no
private `aiortu.x._y` name, and for each `::: module` of a page, the headings of the
module's members are exactly the names its `__all__` exports, or those of its `members:` list (a
curated subset of them, for a subpackage whose `__all__` also serves the rest of aiortu).
"""

from __future__ import annotations

import html
import importlib
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

import aiortu

ROOT = Path(__file__).resolve().parents[2]
API = ROOT / "docs" / "api"
RAW_ROLE = re.compile(r":(?:py:)?(?:class|func|meth|attr|mod|data|exc|obj|const):`?")
PRIVATE = re.compile(r"\baiortu(?:\.\w+)*\._[A-Za-z]\w*")
DIRECTIVE = re.compile(r"^::: (?P<module>\S+)\n(?P<options>(?:[ \t]+.*\n)*)", re.M)


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    directory = tmp_path_factory.mktemp("site")
    result = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", directory],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
        cwd=ROOT,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"},
    )
    assert result.returncode == 0, result.stdout + result.stderr
    return directory


def api_pages() -> list[str]:
    return sorted(path.stem for path in API.glob("*.md"))


def shown_text(page_html: str) -> str:
    """What a reader sees of a page's article: its text, tags and attributes removed."""
    article = page_html[page_html.find("<article") : page_html.rfind("</article>")]
    article = re.sub(r"<(script|style)\b.*?</\1>", " ", article, flags=re.S)
    return html.unescape(re.sub(r"<[^>]+>", " ", article))


def rendered(site: Path, page: str) -> str:
    folder = site / "api" if page == "index" else site / "api" / page
    return (folder / "index.html").read_text(encoding="utf-8")


def test_every_api_page_is_in_the_nav() -> None:
    nav = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    for page in api_pages():
        assert f"api/{page}.md" in nav, page


@pytest.mark.parametrize("page", api_pages())
def test_an_api_page_shows_no_raw_role_and_no_private_name(site: Path, page: str) -> None:
    text = shown_text(rendered(site, page))
    assert text.strip()
    for pattern in (RAW_ROLE, PRIVATE):
        found = sorted({match.group(0) for match in pattern.finditer(text)})
        assert found == [], f"api/{page}: {found}"


def test_the_check_sees_a_raw_role_and_a_private_name() -> None:
    text = shown_text("<article><p>:class:`~aiortu.master._client.Master`</p></article>")
    assert RAW_ROLE.search(text)
    assert PRIVATE.search(text)


@pytest.mark.parametrize("page", api_pages())
def test_an_api_page_documents_exactly_what_its_modules_export(site: Path, page: str) -> None:
    source = (API / f"{page}.md").read_text(encoding="utf-8")
    ids = set(re.findall(r'<h[2-6] id="(aiortu[\w.]*)"', rendered(site, page)))
    modules = {directive.group("module") for directive in DIRECTIVE.finditer(source)}
    for directive in DIRECTIVE.finditer(source):
        module_name = directive.group("module")
        assert module_name in ids, module_name
        if "members: false" in directive.group("options"):
            continue
        module = importlib.import_module(module_name)
        prefix = module_name + "."
        members = {i.removeprefix(prefix) for i in ids if i.startswith(prefix)}
        members = {name for name in members if "." not in name}
        members -= {other.removeprefix(prefix) for other in modules}
        chosen = chosen_members(directive.group("options"))
        if chosen is None:
            assert members == set(module.__all__), module_name
        else:
            # A curated list: the names users need, each exported, each rendered.
            assert chosen <= set(module.__all__), module_name
            assert members == chosen, module_name


def chosen_members(options: str) -> set[str] | None:
    """The names of a directive's `members:` list, or None when it has none."""
    block = re.search(r"^\s+members:\n((?:\s+- \w+\n)+)", options, re.M)
    if block is None:
        return None
    return set(re.findall(r"- (\w+)", block.group(1)))


def test_a_curated_members_list_is_read() -> None:
    options = "    options:\n      members:\n        - Receiver\n        - Role\n"
    assert chosen_members(options) == {"Receiver", "Role"}
    assert chosen_members("    options:\n      members: false\n") is None


def test_the_page_of_top_level_names_lists_what_aiortu_exports(site: Path) -> None:
    table = (API / "aiortu.md").read_text(encoding="utf-8")
    listed = set(re.findall(r"^\| \[`(\w+)`\]\[", table, re.M))
    assert listed == set(aiortu.__all__) - {"__version__"}
    links = re.findall(r'<a class="autorefs[^"]*"[^>]*href="([^"]+)"', rendered(site, "aiortu"))
    assert len(links) >= len(listed)


def test_no_page_shows_the_markers_of_the_code_tests(site: Path) -> None:
    pages = sorted(site.rglob("index.html"))
    assert len(pages) > 10
    for page in pages:
        assert "<!-- test:" not in shown_text(page.read_text(encoding="utf-8")), page


def test_the_state_diagrams_show_without_a_script(site: Path) -> None:
    page = (site / "protocol" / "index.html").read_text(encoding="utf-8")
    drawn = (ROOT / "docs" / "protocol.md").read_text(encoding="utf-8").count("```mermaid")
    assert drawn >= 3
    assert page.count('<svg class="state-diagram"') == drawn
    # No Mermaid block is left, so the theme loads no Mermaid script from a CDN.
    assert "mermaid" not in page
    assert "stateDiagram-v2" not in shown_text(page)


def test_the_benchmarks_page_has_one_title(site: Path) -> None:
    page = (site / "benchmarks" / "index.html").read_text(encoding="utf-8")
    article = page[page.find("<article") : page.rfind("</article>")]
    titles = re.findall(r"<h[12][^>]*>(.*?)</h[12]>", article, re.S)
    shown = [html.unescape(re.sub(r"<[^>]+>", "", title)).strip(" ¶") for title in titles]
    assert shown.count("Benchmarks") == 1


def test_the_home_page_links_the_newcomers_pages(site: Path) -> None:
    page = (site / "index.html").read_text(encoding="utf-8")
    article = page[page.find("<article") : page.rfind("</article>")]
    for target in ("getting-started/", "cli/", "gateway/"):
        assert f'href="{target}"' in article, target
