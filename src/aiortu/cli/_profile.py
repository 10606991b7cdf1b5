"""`aiortu profile`: check device profiles, and read and write a device's points by name.

    aiortu profile check meter.toml                  the profile's summary, or its first error
    aiortu profile read PORT --unit 1 --profile meter.toml [--point NAME ...]
    aiortu profile write PORT --unit 1 --profile meter.toml POINT VALUE
    aiortu profile list                              the profiles aiortu ships
    aiortu profile reference                         the format reference, in Markdown

A bad profile is one line naming the file, the line, the point and the key (exit 2).
`aiortu poll --profile` and `aiortu serve --profile` poll and serve the same files.
"""

from __future__ import annotations

import argparse
import json
import random
import sys
from collections.abc import Awaitable, Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

import anyio

from aiortu.cli import SUMMARIES, CommandFailed, Subparsers
from aiortu.cli._master import (
    EXIT_CODES_HELP,
    UsageError,
    add_line_options,
    open_from_args,
    run_master,
    unit,
    until_signal,
)
from aiortu.core.model import (
    Profile,
    ReadPlan,
    Value,
    check_write,
    find_profile,
    load_profile,
    schema_reference,
    shipped_profiles,
)
from aiortu.errors import ConfigError, InvalidValue

if TYPE_CHECKING:
    from aiortu.core.serial import LineSettings
    from aiortu.slave import MemoryStore, ProfileStore

__all__ = (
    "report_matches",
    "open_profile",
    "open_profiles",
    "register",
    "run_poll",
    "serve_profile",
)

_EXAMPLES = f"""\
examples:
  aiortu profile check meter.toml
  aiortu profile import home-assistant configuration.yaml --out-dir profiles/
      a profile per unit of each hub of the modbus: section
  aiortu profile import evcc sdm-meter.yaml --param usage=grid > meter.toml
  aiortu profile match /dev/ttyUSB0 --unit 1,2,3 --profile meter.toml --profile pump.toml
      which profile each unit matches (identification objects, probes, SunSpec marker)
  aiortu profile walk tcp://10.0.0.9:502 --unit 1 > inverter.toml
      a SunSpec device describes itself: its models as a profile
  aiortu profile sunspec 1 103 160 --repeats 2 --value m103.W=1500 > sim.toml
      a simulated SunSpec device, to serve with 'aiortu serve --profile sim.toml'
  aiortu profile read /dev/ttyUSB0 --unit 1 --profile eastron-sdm630 --point frequency
      two points of a shipped profile (a name from 'aiortu profile list', or a file)
  aiortu profile write tcp://10.0.0.7:502 --unit 1 --profile meter.toml demand_period 15
  aiortu poll /dev/ttyUSB0 --unit 1,2 --profile meter.toml
  aiortu serve tcp://127.0.0.1:5020 --profile meter.toml --unit 1 --move 1

{EXIT_CODES_HELP}"""


def open_profile(name: str) -> Profile:
    """The profile in file `name`, or the shipped profile called `name`; a
    [`ConfigError`][aiortu.errors.ConfigError] naming the shipped ones when it is neither."""
    path = find_profile(name)
    if path is None:
        known = ", ".join(shipped_profiles())
        raise ConfigError(name, "(file)", f"no such file, nor a shipped profile (one of: {known})")
    return load_profile(path)


def register(subparsers: Subparsers) -> None:
    """Add the `profile` subcommand to `subparsers`."""
    parser = subparsers.add_parser(
        "profile",
        help=SUMMARIES["profile"],
        description="Check device profiles (TOML), and read or write points by name.",
        epilog=_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    check = actions.add_parser("check", help="check profiles and summarise them")
    check.add_argument("files", nargs="+", metavar="FILE", help="profiles to check")
    check.set_defaults(run=_check)
    actions.add_parser("list", help="the shipped profiles").set_defaults(run=_list)
    reference = actions.add_parser("reference", help="print the format reference (Markdown)")
    reference.set_defaults(run=_reference)
    _add_device_actions(actions)
    match = actions.add_parser("match", help="which known profiles units match")
    add_line_options(match)
    match.add_argument("--unit", required=True, help="unit address(es): 1..247, comma-separated")
    match.add_argument(
        "--profile",
        action="append",
        dest="profiles",
        metavar="PROFILE",
        help="a profile file or shipped name to match (default: every shipped profile)",
    )
    match.add_argument("--models-dir", help="SunSpec's model definitions (default: pysunspec2's)")
    match.set_defaults(run=_match)
    walk = actions.add_parser("walk", help="walk a SunSpec device and print its profile")
    add_line_options(walk)
    walk.add_argument("--unit", type=unit, required=True, help="unit address 1..247")
    walk.add_argument("--models-dir", help="SunSpec's model definitions (default: pysunspec2's)")
    walk.set_defaults(run=_walk)
    imports = actions.add_parser("import", help="convert Home Assistant or evcc files")
    imports.add_argument("kind", choices=("home-assistant", "evcc"), help="the file's kind")
    imports.add_argument("file", metavar="FILE", help="the YAML file")
    imports.add_argument(
        "--param", action="append", default=[], metavar="NAME=VALUE", help="evcc parameters"
    )
    imports.add_argument(
        "--out-dir", help="write each profile as a file there (default: print them)"
    )
    imports.set_defaults(run=_import)
    layout = actions.add_parser("sunspec", help="print the profile of a simulated SunSpec device")
    layout.add_argument("models", nargs="+", type=int, metavar="MODEL", help="model ids, in order")
    layout.add_argument("--base", type=int, choices=(40000, 50000, 0), default=40000)
    layout.add_argument("--repeats", type=int, default=1, help="instances of repeating groups (1)")
    layout.add_argument("--value", action="append", default=[], metavar="NAME=VALUE")
    layout.add_argument("--models-dir", help="SunSpec's model definitions (default: pysunspec2's)")
    layout.set_defaults(run=_sunspec)


def _add_device_actions(actions: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The actions that talk to a device: `read` and `write` by name."""
    read = actions.add_parser("read", help="read points of a device by name")
    add_line_options(read)
    read.add_argument("--unit", type=unit, required=True, help="unit address 1..247")
    read.add_argument("--profile", required=True, help="a profile file or a shipped name")
    read.add_argument(
        "--point", action="append", dest="points", metavar="NAME", help="a point (all if none)"
    )
    read.add_argument("--json", action="store_true", help="print one JSON object")
    read.set_defaults(run=_read)
    write = actions.add_parser("write", help="write a point of a device by name")
    add_line_options(write)
    write.add_argument("--unit", type=unit, required=True, help="unit address 1..247")
    write.add_argument("--profile", required=True, help="a profile file or a shipped name")
    write.add_argument("point", metavar="POINT", help="the point to write")
    write.add_argument("value", metavar="VALUE", help="a number, true/false, or a name")
    write.set_defaults(run=_write)


def _failed(error: ConfigError | InvalidValue, command: str = "profile") -> int:
    print(f"aiortu {command}: error: {error}", file=sys.stderr)
    return 2


def summary(profile: Profile) -> str:
    """What `check` says of a good profile: the device, its points, its reads per class."""
    device = profile.device
    lines = [
        f"{profile.source}: {device.manufacturer} {device.model}, {len(profile.points)} points"
    ]
    for poll_class, interval in profile.poll_classes.items():
        points = profile.points_of(poll_class)
        if points:
            reads = len(ReadPlan(profile, points).reads)
            lines.append(
                f"  {poll_class}: {len(points)} points in {reads} reads every {interval:g} s"
            )
    return "\n".join(lines)


def _check(args: argparse.Namespace) -> int:
    for name in args.files:
        try:
            print(summary(open_profile(name)), flush=True)
        except ConfigError as error:
            return _failed(error)
    return 0


def _list(args: argparse.Namespace) -> int:
    for name, path in shipped_profiles().items():
        device = load_profile(path).device
        print(f"{name}  {device.manufacturer} {device.model}: {device.description}")
    return 0


def _reference(args: argparse.Namespace) -> int:
    sys.stdout.write(schema_reference())
    return 0


def _parse_value(text: str) -> object:
    lowered = text.strip().lower()
    if lowered in ("true", "on"):
        return True
    if lowered in ("false", "off"):
        return False
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def _show(value: object) -> str:
    if isinstance(value, tuple):
        return ",".join(value) or "-"
    return "-" if value is None else str(value)


def _read(args: argparse.Namespace) -> int:
    from aiortu.master import Device

    try:
        profile = open_profile(args.profile)
        names = args.points or [p.name for p in profile.points]
        for name in names:
            profile.point(name)  # an unknown name fails before the port opens
    except (ConfigError, InvalidValue) as error:
        return _failed(error)

    async def body() -> int:
        async with open_from_args(args) as master:
            device = Device(master, args.unit, profile)
            readings = await device.read()
        failed = 0
        shown = {name: readings[name] for name in names}
        if args.json:
            document = {n: r.value for n, r in shown.items()}
            print(json.dumps({"unit": args.unit, "values": document}), flush=True)
        for name, reading in shown.items():
            if not reading.ok:
                failed += 1
                print(f"{name}: {reading.error}", file=sys.stderr)
            elif not args.json:
                line = f"{name} {_show(reading.value)} {reading.unit_of_measurement}"
                print(line.rstrip(), flush=True)
        return 1 if failed else 0

    return run_master(args, body)


def _write(args: argparse.Namespace) -> int:
    from aiortu.master import Device

    value = _parse_value(args.value)
    try:
        profile = open_profile(args.profile)
        check_write(profile.point(args.point), value)  # refused before the port opens
    except ConfigError as error:
        return _failed(error)
    except InvalidValue as error:
        return _failed(
            InvalidValue(error.field, value, error.allowed, message=f"{profile.source}: {error}")
        )

    async def body() -> int:
        async with open_from_args(args) as master:
            await Device(master, args.unit, profile).write(args.point, value)
        return 0

    return run_master(args, body)


def _units(text: str | None) -> list[int]:
    if not text:
        raise UsageError("--unit is needed with a profile (one unit, or several comma-separated)")
    return [unit(part) for part in text.split(",")]


def run_poll(args: argparse.Namespace) -> int:
    """`aiortu poll --profile FILE --unit U[,U...]`: every point of each unit, each poll class
    on its interval, one line per reading (`UNIT NAME VALUE UNIT`) or one JSON object each."""
    from aiortu.master import Device, ProfilePoller, Reading

    try:
        profile = open_profile(args.profile)
    except ConfigError as error:
        return _failed(error, "poll")

    def show(reading: Reading) -> None:
        measure = reading.unit_of_measurement
        if args.json:
            value = reading.value if reading.ok else None
            document = {"unit": reading.unit, "name": reading.name, "value": value}
            print(json.dumps({**document, "unit_of_measurement": measure}), flush=True)
        else:
            shown = _show(reading.value) if reading.ok else f"error: {reading.error}"
            print(f"{reading.unit} {reading.name} {shown} {measure}".rstrip(), flush=True)

    async def body() -> int:
        units = _units(args.unit)
        async with open_from_args(args, reconnect=args.reconnect) as master:
            devices = [Device(master, u, profile) for u in units]
            poller = ProfilePoller(devices, on_reading=show)
            await until_signal(lambda: poller.run(cycles=args.cycles, duration=args.duration))
        return 0

    return run_master(args, body)


def serve_profile(
    args: argparse.Namespace,
    serve: Callable[[argparse.Namespace, Mapping[int, MemoryStore]], Awaitable[int]],
) -> int:
    """`aiortu serve --profile FILE [--unit U] [--move S]`: the profile's simulated device on
    unit U, served by `serve` (the serve command's loop); with `--move`, its measurements move
    every S seconds."""
    from aiortu.cli._arguments import resolve_line_settings
    from aiortu.cli._messages import library_warnings_on_stderr
    from aiortu.slave import ProfileStore

    try:
        store = ProfileStore(open_profile(args.profile))
    except ConfigError as error:
        print(f"aiortu serve: error: {error}", file=sys.stderr)
        return 2
    if not 1 <= args.unit <= 247:
        print(f"aiortu serve: error: --unit {args.unit} is outside 1..247", file=sys.stderr)
        return 2
    resolve_line_settings(args)

    async def moving() -> int:
        failure: CommandFailed | None = None
        code = 0
        async with anyio.create_task_group() as tasks:
            if args.move:
                tasks.start_soon(_move, store, args.move)
            try:
                code = await serve(args, {args.unit: store})
            except CommandFailed as error:
                failure = error
            tasks.cancel_scope.cancel()
        # Raised out here, not wrapped in the task group's ExceptionGroup.
        if failure is not None:
            raise failure
        return code

    with library_warnings_on_stderr("serve"):
        return anyio.run(moving)


async def _move(store: ProfileStore, every: float) -> None:
    rng = random.Random()
    while True:
        await anyio.sleep(every)
        store.move(rng)


_ATTRIBUTION = (
    "Points and their names, types, units and scale factors come from SunSpec's model\n"
    "definitions (SunSpec Alliance, Apache License 2.0, as pysunspec2 ships them)."
)


def _walk(args: argparse.Namespace) -> int:
    from aiortu.core.model import SunSpecModels, dump_profile
    from aiortu.master import walk_sunspec

    try:
        models = SunSpecModels.locate(args.models_dir)
    except ConfigError as error:
        return _failed(error)

    async def body() -> int:
        async with open_from_args(args) as master:
            found = await walk_sunspec(master, args.unit, models=models)
        if found is None:
            print(f"aiortu profile: unit {args.unit} holds no SunSpec marker", file=sys.stderr)
            return 1
        for warning in found.warnings:
            print(f"aiortu profile: {warning}", file=sys.stderr)
        listed = ", ".join(str(m.id) for m in found.models)
        comment = f"SunSpec device at unit {args.unit}: models {listed}.\n{_ATTRIBUTION}"
        sys.stdout.write(dump_profile(found.profile, comment))
        return 0

    return run_master(args, body)


def _sunspec(args: argparse.Namespace) -> int:
    from aiortu.core.model import PointType, SunSpecModels, dump_profile, sunspec_layout

    texts = dict(item.partition("=")[::2] for item in args.value)
    try:
        models = SunSpecModels.locate(args.models_dir)
        blank = sunspec_layout(models, args.models, base=args.base, repeats=args.repeats)
        values: dict[str, Value] = {}
        for name, text in texts.items():
            kind = blank.point(name.strip()).type
            parsed = text if kind in (PointType.STRING, PointType.ENUM) else _parse_value(text)
            values[name.strip()] = parsed  # type: ignore[assignment]  # checked when laid out
        profile = sunspec_layout(
            models,
            args.models,
            base=args.base,
            repeats=args.repeats,
            values=values,
            manufacturer=texts.get("m1.Mn", "aiortu"),
            model=texts.get("m1.Md", "SunSpec device"),
        )
    except (ConfigError, InvalidValue) as error:
        return _failed(error)
    listed = " ".join(map(str, args.models))
    comment = (
        f"A simulated SunSpec device: models {listed} from {args.base}, made by\n"
        f"'aiortu profile sunspec' (the values given on its command line).\n{_ATTRIBUTION}"
    )
    sys.stdout.write(dump_profile(profile, comment))
    return 0


def _yaml(path: str) -> object:
    """The YAML at `path`; PyYAML is imported only here, and its absence said in one line."""
    try:
        import yaml
    except ImportError:
        raise CommandFailed("reading YAML needs PyYAML: pip install 'aiortu[import]'") from None
    try:
        with open(path, encoding="utf-8") as file:
            return yaml.safe_load(file)
    except OSError as error:
        raise CommandFailed(f"{path}: cannot be read: {error.strerror}") from None
    except yaml.YAMLError as error:
        raise CommandFailed(f"{path}: not YAML: {error}".replace("\n", " ")) from None


def _import(args: argparse.Namespace) -> int:
    from aiortu.core.model import dump_profile, profile_from_evcc, profiles_from_home_assistant

    document = _yaml(args.file)
    source = Path(args.file).name
    try:
        if args.kind == "home-assistant":
            found = {
                f"{hub}-unit{unit}": (profile, f"Unit {unit} of hub {hub!r} of {source}.")
                for (hub, unit), profile in profiles_from_home_assistant(document, source).items()
            }
        else:
            import yaml

            if not isinstance(document, dict):
                raise ConfigError(source, "(file)", "not an evcc template")
            params = dict(item.partition("=")[::2] for item in args.param)
            result = profile_from_evcc(document, yaml.safe_load, params=params, source=source)
            for skipped in result.skipped:
                print(f"aiortu profile: skipped {skipped}", file=sys.stderr)
            found = {Path(args.file).stem: (result.profile, f"From the evcc template {source}.")}
    except ConfigError as error:
        return _failed(error)
    for name, (profile, comment) in found.items():
        text = dump_profile(profile, comment)
        if args.out_dir is None:
            sys.stdout.write(text if len(found) == 1 else f"# --- {name}.toml\n{text}\n")
            continue
        target = Path(args.out_dir) / f"{name}.toml"
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(text, encoding="utf-8")
        print(target)
    return 0


def _match(args: argparse.Namespace) -> int:
    from aiortu.core.model import SunSpecModels
    from aiortu.master import match_profiles

    try:
        names = args.profiles or list(shipped_profiles())
        profiles = [open_profile(name) for name in names]
    except ConfigError as error:
        return _failed(error)
    try:
        models: SunSpecModels | None = SunSpecModels.locate(args.models_dir)
    except ConfigError:
        models = None  # no definitions: the SunSpec marker is not looked for

    async def body() -> int:
        units = _units(args.unit)
        async with open_from_args(args) as master:
            for unit in units:
                found = await match_profiles(master, unit, profiles, sunspec=models)
                if not found:
                    print(f"unit {unit}: no known profile matches", flush=True)
                for match in found:
                    device = match.profile.device
                    where = match.profile.source
                    by = ", ".join(match.by)
                    print(f"unit {unit}: {device.manufacturer} {device.model} ({where}) by {by}")
        return 0

    return run_master(args, body)


def open_profiles(names: Sequence[str]) -> list[Profile]:
    """The profiles `names` (files or shipped names; every shipped profile when empty), each
    as `open_profile` opens it."""
    return [open_profile(name) for name in names or shipped_profiles()]


async def report_matches(
    port: str,
    found: Sequence[tuple[int, LineSettings]],
    profiles: Sequence[Profile],
    *,
    response_timeout: float,
    out: TextIO,
) -> None:
    """For `aiortu scan --profile`: which of `profiles` (opened by `open_profiles` before the
    scan, so that a bad one costs no scan) each unit `found` (with the setting it answered at)
    matches, one line each, reading the unit at that setting."""
    from aiortu.core.model import SunSpecModels
    from aiortu.master import match_profiles, open_master

    try:
        models: SunSpecModels | None = SunSpecModels.locate()
    except ConfigError:
        models = None
    by_setting: dict[LineSettings, list[int]] = {}
    for address, settings in found:
        by_setting.setdefault(settings, []).append(address)
    for settings, units in by_setting.items():
        async with open_master(
            port,
            baudrate=settings.baudrate,
            parity=str(settings.parity),
            stopbits=settings.stopbits,
            timeout=response_timeout,
            retries=0,
            reconnect=False,
        ) as master:
            for address in sorted(set(units)):
                matches = await match_profiles(master, address, profiles, sunspec=models)
                names_found = [
                    f"{m.profile.device.manufacturer} {m.profile.device.model} "
                    f"({m.profile.source}, by {', '.join(m.by)})"
                    for m in matches
                ]
                out.write(f"unit {address}: {'; '.join(names_found) or 'no known profile'}\n")
    out.flush()
