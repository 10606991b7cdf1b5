"""The definitions of aiortu's exceptions; see [`aiortu.errors`][aiortu.errors] for the tree.

They live in the core because the sans-IO core raises them and imports nothing from the
rest of the package. Users import them from [`aiortu.errors`][aiortu.errors] or `aiortu`.
"""

from __future__ import annotations

import enum

from aiortu.core.codes import ExceptionCode

__all__ = (
    "CRCError",
    "ConfigError",
    "ConnectionLost",
    "ExceptionResponse",
    "FrameError",
    "InvalidValue",
    "InvalidRequest",
    "LRCError",
    "MalformedPDU",
    "ModbusError",
    "PortBusy",
    "PortError",
    "PortNotFound",
    "PortPermissionDenied",
    "ResponseTimeout",
    "UnitOffline",
    "UnitSkipped",
    "UnsupportedSettings",
)


class ModbusError(Exception):
    """The base of every error aiortu raises on purpose."""


def _describe_range(allowed: object) -> str:
    if isinstance(allowed, range):
        if allowed.step == 1:
            return f"{allowed.start}..{allowed.stop - 1}"
        return f"{allowed.start}..{allowed.stop - 1} in steps of {allowed.step}"
    return str(allowed)


_SHOWN_LENGTH = 60
"""How much of a value a message shows."""


def _show(value: object) -> str:
    """`value` as a message shows it: the literal of a short plain value, else its type
    (never an object's repr with its address, never a whole long list)."""
    if isinstance(value, enum.Enum):
        return f"{type(value).__name__}.{value.name}"
    if value is None or isinstance(value, int | float | str | bytes | bytearray | list | tuple):
        shown = repr(value)
        if len(shown) <= _SHOWN_LENGTH:
            return shown
        if isinstance(value, str | bytes | bytearray):
            return f"{shown[: _SHOWN_LENGTH - 4]}...{shown[-1]}"
        if isinstance(value, list | tuple):
            return f"a {type(value).__name__} of {len(value)} items"
    name = type(value).__name__
    return f"{'an' if name[0] in 'AEIOUaeiou' else 'a'} {name}"


def _sentence(field: str, shown: str, allowed: object) -> str:
    if isinstance(allowed, range):
        return f"{field} = {shown} is outside the allowed range {_describe_range(allowed)}"
    return f"{field} must be {allowed}, not {shown}"  # a description, not a range


class InvalidValue(ModbusError, ValueError):
    """A field or a setting is outside its allowed range. Caused by the caller.

    Raised while building a request, a response or line settings, before any byte exists.
    [`field`][aiortu.errors.InvalidValue] names the field, [`value`][aiortu.errors.InvalidValue] is
    what was given and [`allowed`][aiortu.errors.InvalidValue] describes what the spec permits (a
    `range` or a short text); [`detail`][aiortu.errors.InvalidValue] says more, or is empty.
    """

    def __init__(
        self,
        field: str,
        value: object,
        allowed: object,
        detail: str = "",
        *,
        message: str | None = None,
    ) -> None:
        self.field = field
        self.value = value
        self.allowed = allowed
        self.detail = detail
        if message is None:
            message = _sentence(field, _show(value), allowed)
        if detail:
            message = f"{message}: {detail}"
        super().__init__(message)


class InvalidRequest(InvalidValue):
    """A request the spec forbids, such as unit 0 for a read or a count of 0. Caused by the caller.

    Raised before anything is sent, so the line is untouched.
    """


class ExceptionResponse(ModbusError):
    """The device answered with a Modbus exception response. Caused by the peer.

    The exchange itself worked: the device understood the frame and refused the request.
    [`code`][aiortu.errors.ExceptionResponse] is the exception code the device sent (an
    `ExceptionCode` when it is one the spec defines, else the raw `int`),
    [`function_code`][aiortu.errors.ExceptionResponse] is the function code of the request, and
    [`unit`][aiortu.errors.ExceptionResponse] the device's address when known.
    """

    def __init__(
        self, code: int, function_code: int | None = None, unit: int | None = None
    ) -> None:
        try:
            self.code: int = ExceptionCode(code)
        except ValueError:
            self.code = code
        self.function_code = function_code
        self.unit = unit
        name = self.code.name if isinstance(self.code, enum.Enum) else "UNKNOWN"
        where = []
        if unit is not None:
            where.append(f"unit {unit}")
        if function_code is not None:
            where.append(f"function 0x{function_code:02X}")
        suffix = f" from {', '.join(where)}" if where else ""
        super().__init__(f"exception response {name} (0x{code:02X}){suffix}")


class ResponseTimeout(ModbusError, TimeoutError):
    """No valid reply arrived within the response timeout. Caused by the peer or the line.

    The device may be off, at another address or baud rate, or the reply was too corrupted
    to recognise. Also a `TimeoutError`, so generic timeout handling catches it.
    """


class FrameError(ModbusError):
    """Bytes arrived that do not make a valid frame. Caused by the peer or the line.

    [`reason`][aiortu.errors.FrameError] is a short machine-readable word (`"crc"`, `"length"`,
    `"content"`, ...), and the message explains it.
    """

    reason = "frame"

    def __init__(self, message: str, *, reason: str | None = None) -> None:
        if reason is not None:
            self.reason = reason
        super().__init__(message)


class CRCError(FrameError):
    """The CRC of a frame does not match its content. Caused by the line.

    Noise, a collision of two transmitters, or line settings (baud rate, parity) that
    differ between the ends.
    """

    reason = "crc"

    def __init__(self, received: int, computed: int) -> None:
        self.received = received
        self.computed = computed
        super().__init__(
            f"CRC mismatch: frame carries 0x{received:04X}, content gives 0x{computed:04X}"
        )


class LRCError(FrameError):
    """The LRC of an ASCII frame does not match its content. Caused by the line.

    The ASCII framing's counterpart of [`CRCError`][aiortu.errors.CRCError]: noise, or line
    settings that differ between the ends.
    """

    reason = "lrc"

    def __init__(self, received: int, computed: int) -> None:
        self.received = received
        self.computed = computed
        super().__init__(
            f"LRC mismatch: frame carries 0x{received:02X}, content gives 0x{computed:02X}"
        )


class MalformedPDU(FrameError):
    """A frame with a good CRC whose content breaks the spec. Caused by the peer.

    [`field`][aiortu.errors.MalformedPDU], [`value`][aiortu.errors.MalformedPDU] and
    [`allowed`][aiortu.errors.MalformedPDU] name what is wrong when it is one field.
    [`exception_code`][aiortu.errors.MalformedPDU] is the Modbus exception a slave answers such a
    request with (`ILLEGAL_DATA_VALUE` unless the function itself is unknown).
    """

    reason = "content"

    def __init__(
        self,
        message: str,
        *,
        field: str | None = None,
        value: object = None,
        allowed: object = None,
        exception_code: int = 0x03,
    ) -> None:
        self.field = field
        self.value = value
        self.allowed = allowed
        self.exception_code = exception_code
        if field is not None:
            message = f"{message}: {field} = {value!r}, allowed {_describe_range(allowed)}"
        super().__init__(message)


class ConnectionLost(ModbusError):
    """The byte stream under the line closed or failed. Caused by the line.

    A USB adapter unplugged, a TCP connection to a serial device server dropped, or the
    other end of a virtual line closed. Requests in flight fail with this error.
    """


class PortError(ModbusError):
    """A port could not be opened as asked. Caused by the environment.

    [`port`][aiortu.errors.PortError] names the device path or URL.
    """

    def __init__(self, port: str, message: str) -> None:
        self.port = port
        super().__init__(f"{port}: {message}")


class PortNotFound(PortError):
    """No such serial device, pty or host."""


class PortBusy(PortError):
    """Another program has the port open (aiortu opens serial ports exclusively)."""


class PortPermissionDenied(PortError):
    """The user may not open the port (on Linux, usually missing from the `dialout` group)."""


class UnsupportedSettings(PortError):
    """The port or the OS refuses the requested line settings (baud rate, parity, RS-485)."""


class UnitOffline(ResponseTimeout):
    """The unit is marked offline and the master fails fast: nothing was sent. Caused by the peer.

    Raised only with `fail_fast_offline=True`, between probes. Also a
    [`ResponseTimeout`][aiortu.errors.ResponseTimeout], since the unit has not been answering.
    """

    def __init__(self, unit: int, failures: int) -> None:
        self.unit = unit
        super().__init__(
            f"unit {unit} is offline after {failures} consecutive failures; "
            "not sent (fail_fast_offline)"
        )


class UnitSkipped(ResponseTimeout):
    """The poller skipped a read of an offline unit until its next probe. Caused by the peer.

    Nothing was sent. Also a [`ResponseTimeout`][aiortu.errors.ResponseTimeout], since the unit has
    not been answering.
    """

    def __init__(self, unit: int, next_probe_in: float) -> None:
        self.unit = unit
        self.next_probe_in = next_probe_in
        super().__init__(f"unit {unit} is offline; next probe in {next_probe_in:.1f} s")


class ConfigError(ModbusError, ValueError):
    """A device description file is wrong. Caused by the caller (the file's author).

    The message is one line, `FILE: KEY: PROBLEM`; [`source`][aiortu.errors.ConfigError],
    [`key`][aiortu.errors.ConfigError] (a key path such as `slave[0].coils[1].count`) and
    [`problem`][aiortu.errors.ConfigError] hold the parts.
    """

    def __init__(self, source: str, key: str, problem: str) -> None:
        super().__init__(f"{source}: {key}: {problem}")
        self.source = source
        self.key = key
        self.problem = problem
