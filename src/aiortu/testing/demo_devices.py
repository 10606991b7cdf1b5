"""Deprecated: internal now (the `aiortu demo` command's). Importing this module warns once."""

from aiortu._moved import forward_internal

__getattr__ = forward_internal(
    __name__,
    "aiortu.cli._demo_devices",
    "serve devices of your own from aiortu.slave.MemoryStore, as "
    "examples/poll_several_devices.py does",
)
