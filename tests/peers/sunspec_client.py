"""pysunspec2's own client, run in pysunspec2's venv: scan a SunSpec device over Modbus TCP and
print the top-level points of each model it found, as one JSON object.

    python sunspec_client.py PORT UNIT [WRITE_MODEL WRITE_POINT WRITE_VALUE]

The optional write sets a point through pysunspec2 (scaled value) before the scan's values
are printed. Output: {"models": {id: {point: value}}}, values as pysunspec2 computes them
(scale factors applied; None for "not implemented").
"""

import json
import sys

import sunspec2.modbus.client as client


def main() -> None:
    port, unit = int(sys.argv[1]), int(sys.argv[2])
    device = client.SunSpecModbusClientDeviceTCP(
        slave_id=unit, ipaddr="127.0.0.1", ipport=port, timeout=5
    )
    device.scan()
    if len(sys.argv) > 3:
        model_id, point, value = int(sys.argv[3]), sys.argv[4], float(sys.argv[5])
        if value.is_integer():
            value = int(value)
        target = device.models[model_id][0].points[point]
        target.cvalue = value
        target.write()
        device.models[model_id][0].read()
    found = {}
    for model_id, models in device.models.items():
        if isinstance(model_id, int):
            found[model_id] = {name: p.cvalue for name, p in models[0].points.items()}
    device.close()
    print(json.dumps({"models": found}, default=str))


if __name__ == "__main__":
    main()
