"""What a slave answers to Read Device Identification (2B/0E), from its objects.

The spec sorts the objects by id into categories: basic 0x00..0x02 (vendor name, product
code, revision), regular 0x03..0x7F, extended 0x80..0xFF. A stream read returns the
objects of its read code from an object id on (basic: 0x00..0x02, regular: 0x00..0x7F,
extended: 0x00..0xFF), as many as fit one reply; when some are left, the reply says
"more follows" and names the next object id. A stream that starts at an id the device
does not have, in that range, restarts at the first object, as the spec says. An
individual read (04) returns one object, or exception 02 when the device has no such id.
The conformity level says the highest category the device has, with individual access
(0x81, 0x82 or 0x83).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Final

from aiortu.core.codes import DeviceIdReadCode
from aiortu.core.pdu import MAX_PDU_LENGTH, ReadDeviceIdentificationResponse

__all__ = ("CATEGORY_END", "answer_device_identification", "conformity_level")

CATEGORY_END: Final[Mapping[int, int]] = {
    DeviceIdReadCode.BASIC: 0x03,
    DeviceIdReadCode.REGULAR: 0x80,
    DeviceIdReadCode.EXTENDED: 0x100,
}
"""One past the last object id each stream read code covers."""

_HEADER_LENGTH = 7
_OBJECT_HEADER_LENGTH = 2
_INDIVIDUAL_ACCESS = 0x80


def conformity_level(objects: Mapping[int, bytes]) -> int:
    """The conformity level of a device with `objects`, individual access included."""
    if any(object_id >= 0x80 for object_id in objects):
        return _INDIVIDUAL_ACCESS | DeviceIdReadCode.EXTENDED
    if any(object_id >= 0x03 for object_id in objects):
        return _INDIVIDUAL_ACCESS | DeviceIdReadCode.REGULAR
    return _INDIVIDUAL_ACCESS | DeviceIdReadCode.BASIC


def answer_device_identification(
    objects: Mapping[int, bytes], read_code: int, object_id: int
) -> ReadDeviceIdentificationResponse | None:
    """The reply to a read of `read_code` from `object_id`, or `None` for exception 02.

    `None` comes only for an individual read of an object the device does not have.
    """
    level = conformity_level(objects)
    if read_code == DeviceIdReadCode.INDIVIDUAL:
        value = objects.get(object_id)
        if value is None:
            return None
        return ReadDeviceIdentificationResponse(read_code, level, ((object_id, value),))
    end = CATEGORY_END[read_code]
    ids = sorted(key for key in objects if key < end)
    if object_id not in ids:
        object_id = ids[0] if ids else 0
    room = MAX_PDU_LENGTH - _HEADER_LENGTH
    chosen: list[tuple[int, bytes]] = []
    for key in ids:
        if key < object_id:
            continue
        value = objects[key]
        cost = _OBJECT_HEADER_LENGTH + len(value)
        if cost > room:
            return ReadDeviceIdentificationResponse(read_code, level, tuple(chosen), True, key)
        room -= cost
        chosen.append((key, value))
    return ReadDeviceIdentificationResponse(read_code, level, tuple(chosen))
