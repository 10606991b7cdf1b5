"""Methods made from other methods: the unit handles' from the master's operations, the
blocking API's from the async one. The made method shows the name, the docstring and the
signature of the one it is made from (the unit a handle binds taken out), for `help()`,
`inspect.signature` and the API reference; the types come from the wrappers' ParamSpecs."""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any

__all__ = ("derive",)


def derive(
    made: Callable[..., Any],
    source: Callable[..., Any],
    owner: str | None,
    *,
    drop: int = 0,
    doc: str | None = None,
    returns: str | None = None,
) -> None:
    """Give `made`, a method of class `owner` (None: a function), the name, docstring and
    signature of `source`, whose parameters after `self` lose their first `drop`; `doc` and
    `returns` replace the docstring and the return annotation."""
    name = source.__name__
    made.__name__ = name
    made.__qualname__ = name if owner is None else f"{owner}.{name}"
    made.__doc__ = source.__doc__ if doc is None else doc
    signature = inspect.signature(source)
    parameters = list(signature.parameters.values())
    signature = signature.replace(parameters=parameters[:1] + parameters[1 + drop :])
    if returns is not None:
        signature = signature.replace(return_annotation=returns)
    made.__signature__ = signature  # type: ignore[attr-defined]
