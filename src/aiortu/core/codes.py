"""The numbers of the Modbus application protocol, as enums.

Function codes, exception codes, the sub-functions of Diagnostics (08), and the codes of
Read Device Identification (2B/0E). Each is an `enum.IntEnum`, so a member compares
equal to the number on the wire and prints with its name. Beside them, the unit ids each
framing carries ([`UnitIds`][aiortu.core.codes.UnitIds]).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

__all__ = (
    "BROADCAST_UNIT",
    "DeviceIdObject",
    "DeviceIdReadCode",
    "DiagnosticSubFunction",
    "EXCEPTION_BIT",
    "ExceptionCode",
    "FunctionCode",
    "MBAP_UNIT_IDS",
    "MEI_READ_DEVICE_IDENTIFICATION",
    "SERIAL_UNIT_IDS",
    "USER_DEFINED_FUNCTION_CODES",
    "UnitIds",
    "is_user_defined",
)

BROADCAST_UNIT = 0
"""Unit address 0: every slave executes the request and none replies."""


@dataclass(frozen=True, slots=True)
class UnitIds:
    """The unit ids a framing carries, and which of them, if any, is the broadcast."""

    ids: range
    """Every unit id a request may carry."""
    broadcast: int | None
    """The first of `ids` where it is the broadcast (every unit executes the request and none
    answers), or None where there is no broadcast."""

    @property
    def unicast(self) -> range:
        """The ids whose reply is awaited: `ids` less the broadcast."""
        return self.ids if self.broadcast is None else self.ids[1:]


SERIAL_UNIT_IDS = UnitIds(range(248), broadcast=BROADCAST_UNIT)
"""A serial line (RTU or ASCII, on a port or over TCP): 1..247 are units, 0 is the broadcast
(248..255 are reserved)."""

MBAP_UNIT_IDS = UnitIds(range(256), broadcast=None)
"""An MBAP header (Modbus TCP, UDP and TLS): any byte, each a unit whose reply is awaited;
on TCP unit 0 addresses the server itself, and a gateway gives 0 its serial meaning only
when it forwards to a line."""

EXCEPTION_BIT = 0x80
"""Set in the function code of an exception response."""

MEI_READ_DEVICE_IDENTIFICATION = 0x0E
"""The MEI type of Read Device Identification, carried by function code 0x2B."""

USER_DEFINED_FUNCTION_CODES = (*range(65, 73), *range(100, 111))
"""The function codes the spec leaves to users: 65..72 and 100..110."""


def is_user_defined(function_code: int) -> bool:
    """Tell whether `function_code` lies in a range the spec leaves to users."""
    return 65 <= function_code <= 72 or 100 <= function_code <= 110


class FunctionCode(enum.IntEnum):
    """The public function codes that Modbus RTU defines."""

    READ_COILS = 0x01
    READ_DISCRETE_INPUTS = 0x02
    READ_HOLDING_REGISTERS = 0x03
    READ_INPUT_REGISTERS = 0x04
    WRITE_SINGLE_COIL = 0x05
    WRITE_SINGLE_REGISTER = 0x06
    READ_EXCEPTION_STATUS = 0x07
    DIAGNOSTICS = 0x08
    GET_COMM_EVENT_COUNTER = 0x0B
    GET_COMM_EVENT_LOG = 0x0C
    WRITE_MULTIPLE_COILS = 0x0F
    WRITE_MULTIPLE_REGISTERS = 0x10
    REPORT_SERVER_ID = 0x11
    READ_FILE_RECORD = 0x14
    WRITE_FILE_RECORD = 0x15
    MASK_WRITE_REGISTER = 0x16
    READ_WRITE_MULTIPLE_REGISTERS = 0x17
    READ_FIFO_QUEUE = 0x18
    ENCAPSULATED_INTERFACE_TRANSPORT = 0x2B


class ExceptionCode(enum.IntEnum):
    """The exception codes a slave may answer with."""

    ILLEGAL_FUNCTION = 0x01
    ILLEGAL_DATA_ADDRESS = 0x02
    ILLEGAL_DATA_VALUE = 0x03
    SERVER_DEVICE_FAILURE = 0x04
    ACKNOWLEDGE = 0x05
    SERVER_DEVICE_BUSY = 0x06
    MEMORY_PARITY_ERROR = 0x08
    GATEWAY_PATH_UNAVAILABLE = 0x0A
    GATEWAY_TARGET_DEVICE_FAILED_TO_RESPOND = 0x0B


class DiagnosticSubFunction(enum.IntEnum):
    """The sub-functions of Diagnostics (function code 08) on a serial line."""

    RETURN_QUERY_DATA = 0x00
    RESTART_COMMUNICATIONS = 0x01
    RETURN_DIAGNOSTIC_REGISTER = 0x02
    CHANGE_ASCII_INPUT_DELIMITER = 0x03
    FORCE_LISTEN_ONLY_MODE = 0x04
    CLEAR_COUNTERS_AND_DIAGNOSTIC_REGISTER = 0x0A
    RETURN_BUS_MESSAGE_COUNT = 0x0B
    RETURN_BUS_COMMUNICATION_ERROR_COUNT = 0x0C
    RETURN_BUS_EXCEPTION_ERROR_COUNT = 0x0D
    RETURN_SERVER_MESSAGE_COUNT = 0x0E
    RETURN_SERVER_NO_RESPONSE_COUNT = 0x0F
    RETURN_SERVER_NAK_COUNT = 0x10
    RETURN_SERVER_BUSY_COUNT = 0x11
    RETURN_BUS_CHARACTER_OVERRUN_COUNT = 0x12
    CLEAR_OVERRUN_COUNTER_AND_FLAG = 0x14


class DeviceIdReadCode(enum.IntEnum):
    """How much of the device identification to read (Read Device ID code)."""

    BASIC = 0x01
    """Stream the basic objects: vendor name, product code, revision."""
    REGULAR = 0x02
    """Stream the basic and regular objects."""
    EXTENDED = 0x03
    """Stream the basic, regular and extended (private, 0x80..0xFF) objects."""
    INDIVIDUAL = 0x04
    """Read one object, named by its object id."""


class DeviceIdObject(enum.IntEnum):
    """The object ids the spec names; 0x07..0x7F are reserved, 0x80..0xFF are private."""

    VENDOR_NAME = 0x00
    PRODUCT_CODE = 0x01
    MAJOR_MINOR_REVISION = 0x02
    VENDOR_URL = 0x03
    PRODUCT_NAME = 0x04
    MODEL_NAME = 0x05
    USER_APPLICATION_NAME = 0x06
