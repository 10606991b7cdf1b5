"""Every exported class and function names its public home in `__module__`.

`repr()`, tracebacks, pickles and `help()` then show the import users write
(`aiortu.Master`), never the private module the name is written in.
"""

from __future__ import annotations

import importlib
import inspect
import pickle

import pytest

import aiortu
from tests.project.test_public_api import PUBLIC_MODULES

# The command line is an application, not a library: its names are not imported by users.
LIBRARY_MODULES = [
    "aiortu",
    *(name for name in PUBLIC_MODULES if name.split(".")[:2] != ["aiortu", "cli"]),
]


def _exported(module_name: str) -> list[tuple[str, object]]:
    module = importlib.import_module(module_name)
    return [
        (name, value)
        for name in module.__all__
        if inspect.isclass(value := getattr(module, name)) or inspect.isfunction(value)
    ]


@pytest.mark.parametrize("module_name", LIBRARY_MODULES)
def test_each_export_lives_in_a_public_module_that_exports_it(module_name: str) -> None:
    wrong = []
    for name, value in _exported(module_name):
        home = value.__module__  # type: ignore[attr-defined]
        if any(part.startswith("_") for part in home.split(".")):
            wrong.append(f"{name}: {home}")
            continue
        home_module = importlib.import_module(home)
        if name not in home_module.__all__ or getattr(home_module, name) is not value:
            wrong.append(f"{name}: {home} does not export it")
        elif inspect.isclass(value) and "._" in repr(value):
            wrong.append(f"{name}: {value!r}")
    assert wrong == [], f"{module_name} exports names with no public home: {wrong}"


@pytest.mark.parametrize("module_name", LIBRARY_MODULES)
def test_each_export_pickles_by_its_public_name(module_name: str) -> None:
    for _, value in _exported(module_name):
        assert pickle.loads(pickle.dumps(value)) is value


def test_the_top_level_names_show_the_top_level() -> None:
    assert repr(aiortu.Master) == "<class 'aiortu.Master'>"
    assert repr(aiortu.ModbusError) == "<class 'aiortu.ModbusError'>"
    top = [name for name, _ in _exported("aiortu") if name != "gateway"]
    assert [name for name in top if getattr(aiortu, name).__module__ != "aiortu"] == []


def test_a_package_keeps_its_own_names() -> None:
    from aiortu.master import CycleReport
    from aiortu.transport import open_stream

    assert CycleReport.__module__ == "aiortu.master"
    assert open_stream.__module__ == "aiortu.transport"


def test_records_and_errors_still_round_trip() -> None:
    error = pickle.loads(pickle.dumps(aiortu.ModbusError("no reply")))
    assert type(error) is aiortu.ModbusError
    assert str(error) == "no reply"
    settings = aiortu.LineSettings(9600)
    assert pickle.loads(pickle.dumps(settings)) == settings
    assert repr(aiortu.ExceptionCode(2)).startswith("<ExceptionCode.")
