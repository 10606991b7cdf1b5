"""A simulated device served from a profile: the same file a master polls.

    store = aiortu.ProfileStore(aiortu.load_profile("sdm630.toml"))
    store.set_value("l1_voltage", 231.5)
    async with aiortu.serve("tcp://127.0.0.1:5020", {1: store}):
        ...

Each table's points are laid out in blocks that stop at the profile's holes, so a read across a
hole (or past the last point) gets exception 02, as the real device answers; the unused
addresses between points read 0. Every point starts at its `value` from the profile (else at
its `not_available` raw value, else 0).
Read-only points of holding registers refuse writes; the device identification objects come
from the profile's device and its `identify.objects`.
"""

from __future__ import annotations

import math
import random
from collections.abc import Iterable, Sequence
from dataclasses import replace

from aiortu.core.codes import DeviceIdObject, ExceptionCode
from aiortu.core.model import (
    OBJECT_IDS,
    PointType,
    Profile,
    ProfilePoint,
    Table,
    Value,
    check_value,
    decode_point,
    encode_point,
)
from aiortu.slave._store import Block, MemoryStore

__all__ = ("ProfileStore",)


def _blocks(profile: Profile, table: Table) -> list[Block]:
    """Blocks covering `table`'s points, split at every hole."""
    points = sorted((p for p in profile.points if p.table is table), key=lambda p: p.address)
    blocks: list[Block] = []
    start = end = -1
    for point in points:
        split = any(
            h.table is table and h.start < point.address and end <= h.start for h in profile.holes
        )
        if blocks and not split:
            end = max(end, point.stop)
            blocks[-1] = Block(start, end - start)
            continue
        start, end = point.address, point.stop
        blocks.append(Block(start, end - start))
    return blocks


def _identification(profile: Profile) -> dict[int, str]:
    device = profile.device
    objects: dict[int, str] = {
        DeviceIdObject.VENDOR_NAME: device.manufacturer,
        DeviceIdObject.PRODUCT_CODE: device.model,
        DeviceIdObject.MAJOR_MINOR_REVISION: "1.0",
        DeviceIdObject.MODEL_NAME: device.model,
    }
    for name, text in device.identify.objects.items():
        objects[OBJECT_IDS[name]] = text
    return {int(key): text for key, text in objects.items()}


class ProfileStore(MemoryStore):
    """A [`MemoryStore`][aiortu.slave.MemoryStore] laid out by `profile` (see the module
    docstring), with the points' values by name."""

    def __init__(self, profile: Profile) -> None:
        read_only: dict[Table | str, list[range]] = {
            Table.HOLDING_REGISTERS: [
                range(p.address, p.stop)
                for p in profile.points
                if p.table is Table.HOLDING_REGISTERS and not p.writable
            ],
            Table.COILS: [
                range(p.address, p.stop)
                for p in profile.points
                if p.table is Table.COILS and not p.writable
            ],
        }
        super().__init__(
            coils=_blocks(profile, Table.COILS) or None,
            discrete_inputs=_blocks(profile, Table.DISCRETE_INPUTS) or None,
            input_registers=_blocks(profile, Table.INPUT_REGISTERS) or None,
            holding_registers=_blocks(profile, Table.HOLDING_REGISTERS) or None,
            read_only=read_only,
            read_only_exception=ExceptionCode.ILLEGAL_DATA_ADDRESS,
            device_identification=_identification(profile),
        )
        self.profile = profile
        """The profile served."""
        # Scale factors first: the values they scale are encoded with them.
        factors = {p.scale_factor for p in profile.points}
        for point in sorted(profile.points, key=lambda p: p.name not in factors):
            if point.initial is not None:
                self.set_value(point.name, point.initial)
            elif point.not_available is not None and point.type is PointType.STRING:
                self.set_value(point.name, "")  # all NULs
            elif point.not_available is not None:
                # A point with no value says so, as the device would.
                raw = replace(point, scale=None, offset=None, scale_factor=None)
                self.set(point.table, point.address, list(encode_point(raw, point.not_available)))

    def _factor(self, point: ProfilePoint) -> int | None:
        if point.scale_factor is None:
            return None
        factor = self.value(point.scale_factor)
        return int(factor) if isinstance(factor, int | float) else 0

    def set_value(self, name: str, value: object) -> None:
        """Set the point `name` to `value` as the device itself (its access and limits do not
        apply; its kind does), scaled with its scale factor's current value."""
        point = self.profile.point(name)
        elements = encode_point(point, check_value(point, value), self._factor(point))
        self.set(point.table, point.address, list(elements))

    def value(self, name: str) -> Value:
        """The current value of the point `name`."""
        point = self.profile.point(name)
        elements: Sequence[int] = self.get(point.table, point.address, point.size)
        return decode_point(point, elements, self._factor(point))

    def move(self, rng: random.Random, names: Iterable[str] | None = None) -> None:
        """Move the numeric points `names` (every read-only float point when None) by a
        random step of about 1 % of their value, as a live device's measurements do."""
        floats = (PointType.F32, PointType.F64)
        points = (
            [self.profile.point(n) for n in names]
            if names is not None
            else [p for p in self.profile.points if p.type in floats and not p.writable]
        )
        for point in points:
            current = self.value(point.name)
            if isinstance(current, int | float) and math.isfinite(current):
                step = (abs(current) * 0.01 or 0.1) * rng.uniform(-1.0, 1.0)
                moved = current + step
                self.set_value(point.name, round(moved) if point.type.is_integer else moved)
