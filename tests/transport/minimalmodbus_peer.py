"""minimalmodbus 2.1.1's ASCII master against a slave, run from a venv of its own (it is not a
test dependency; see tests/transport/test_interop_ascii.py).

    python minimalmodbus_peer.py DEVICE

reads holding registers 0..2 of unit 17 at 19200 8N2 (a pty keeps neither parity nor 7 data
bits), writes 77 to register 3 (function 06) and 1, 2 to registers 4 and 5 (function 16), reads
3..5 back, reads coils 0..3, and prints one line per step.
"""

from __future__ import annotations

import sys

import minimalmodbus

device = minimalmodbus.Instrument(sys.argv[1], 17, mode=minimalmodbus.MODE_ASCII)
device.serial.baudrate = 19200
device.serial.bytesize = 8
device.serial.parity = "N"
device.serial.stopbits = 2
device.serial.timeout = 2.0
print("read", device.read_registers(0, 3))
device.write_register(3, 77, functioncode=6)
device.write_registers(4, [1, 2])
print("read", device.read_registers(3, 3))
print("coils", device.read_bits(0, 4, functioncode=1))
