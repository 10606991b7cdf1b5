"""A griffe extension for the API reference: the methods that a class builds from a table at
import (the unit handles, the broadcast handle, the blocking API), shown as the methods they are.

Static analysis sees `read_coils = on_unit(Operations.read_coils)` as an attribute; this
extension imports the class and documents each such member from the function it holds: its
signature (`__signature__`, the unit taken out) and its docstring, written once on the operation.
"""

from __future__ import annotations

import importlib
import inspect
from typing import Any

import griffe


def _parameter(parameter: inspect.Parameter) -> griffe.Parameter:
    annotation = parameter.annotation
    default = parameter.default
    return griffe.Parameter(
        parameter.name,
        annotation=None if annotation is parameter.empty else str(annotation),
        kind=griffe.ParameterKind(parameter.kind.description),
        default=None if default is parameter.empty else repr(default),
    )


def _function(name: str, made: Any, parent: griffe.Class | griffe.Module) -> griffe.Function:
    signature = inspect.signature(made)
    returns = signature.return_annotation
    function = griffe.Function(
        name,
        parameters=griffe.Parameters(*(_parameter(p) for p in signature.parameters.values())),
        returns=None if returns is signature.empty else str(returns),
        docstring=griffe.Docstring(inspect.cleandoc(made.__doc__ or ""), parent=parent),
        lineno=parent.lineno,
        endlineno=parent.endlineno,
    )
    if inspect.iscoroutinefunction(made):
        function.labels.add("async")
    return function


def _replace(container: griffe.Class | griffe.Module, runtime: Any) -> None:
    for name, member in list(container.members.items()):
        if not isinstance(member, griffe.Attribute) or name.startswith("_"):
            continue
        made = vars(runtime).get(name)
        if inspect.isfunction(made):
            container.set_member(name, _function(name, made, container))


class DerivedMethods(griffe.Extension):
    """Replace each attribute of an aiortu class or module that holds a function by that
    function."""

    def on_module_members(self, *, mod: griffe.Module, **kwargs: Any) -> None:
        if mod.path.startswith("aiortu"):
            _replace(mod, importlib.import_module(mod.path))

    def on_class_members(self, *, cls: griffe.Class, **kwargs: Any) -> None:
        if not cls.path.startswith("aiortu."):
            return
        try:
            runtime = getattr(importlib.import_module(cls.module.path), cls.name)
        except (ImportError, AttributeError):
            return
        _replace(cls, runtime)
