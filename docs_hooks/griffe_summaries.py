"""A Griffe extension for the API pages: each docstring's first paragraph on one line.

mkdocstrings' summary tables show a docstring's first line. Docstrings wrap at the line
length, so a first sentence that takes two lines showed cut in the middle ("Open
`port_or_url` (a serial device path, ... or tcp://host:port for"). Joining the lines of the
first paragraph gives the summary the whole sentence, and changes nothing else: Markdown
joins a paragraph's lines anyway.
"""

from __future__ import annotations

from typing import Any

import griffe


def first_paragraph_on_one_line(text: str) -> str:
    """`text` with the lines of its first paragraph joined by spaces (an indented or fenced
    block that follows the paragraph is left as it is)."""
    lines = text.split("\n")
    end = 0
    while end < len(lines) and lines[end].strip() and not lines[end].startswith(("    ", "```")):
        end += 1
    if end <= 1:
        return text
    joined = " ".join(line.strip() for line in lines[:end])
    return "\n".join([joined, *lines[end:]])


class FirstParagraphSummaries(griffe.Extension):
    """Joins the first paragraph of every docstring loaded (see the module docstring)."""

    def on_object(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None:
            obj.docstring.value = first_paragraph_on_one_line(obj.docstring.value)
