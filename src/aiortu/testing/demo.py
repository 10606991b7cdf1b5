"""Deprecated: internal now (the `aiortu demo` command's). Importing this module warns once."""

from aiortu._moved import forward_internal

__getattr__ = forward_internal(
    __name__,
    "aiortu.cli._demo_system",
    "run `aiortu demo`, or build the same system from aiortu.testing.VirtualBus, "
    "aiortu.slave.Slave and aiortu.master.Poller as examples/poll_several_devices.py does",
)
