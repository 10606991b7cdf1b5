"""Deprecated: internal now; its methods are on [`aiortu.master.Master`][aiortu.master.Master].
Importing this module warns once."""

from aiortu._moved import forward_internal

__getattr__ = forward_internal(
    __name__,
    "aiortu.master._serial_line",
    "its methods are on aiortu.master.Master and aiortu.master.UnitHandle",
)
