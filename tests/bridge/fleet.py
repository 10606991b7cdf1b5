"""A fleet of bridge processes on one machine, for the fleet test and benchmarks/bench_bridge.py:
each `aiortu bridge` on its own virtual line of simulated units, all into one broker."""

from __future__ import annotations

import re
import signal
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

STOPPED = re.compile(
    r"stopped: (?P<values>\d+) values in (?P<messages>\d+) messages, (?P<delivered>\d+) "
    r"delivered, (?P<dropped>\d+) dropped, (?P<waiting>\d+) waiting"
)


def write_profile(path: Path, points: int) -> Path:
    """A device of `points` holding registers (u16 and f32 in turn), one poll class of 1 s."""
    lines = ['[device]\nmanufacturer = "aiortu"\nmodel = "fleet"\n', "[defaults]\nmax_gap = 0\n"]
    address = 0
    for n in range(points):
        kind = "f32" if n % 2 else "u16"
        value = f"{n}.5" if n % 2 else str(n)
        lines.append(
            f'[[point]]\nname = "p{n:02}"\naddress = {address}\ntype = "{kind}"\nvalue = {value}\n'
            f'unit = "W"\nmeta = {{ device_class = "power", state_class = "measurement" }}\n'
        )
        address += 2 if kind == "f32" else 1
    path.write_text("\n".join(lines))
    return path


def write_config(path: Path, *, node: str, units: int, url: str, profile: Path,
                 keepalive: int = 2, publish: str = "every") -> Path:  # fmt: skip
    """The configuration of bridge `node`: `units` devices `NODE-uN` of `profile`."""
    devices = "".join(
        f'[[line.device]]\nname = "{node}-u{u}"\nunit = {u}\nprofile = "{profile}"\n'
        f'publish = "{publish}"\n'
        for u in range(1, units + 1)
    )
    path.write_text(
        f'[broker]\nurl = "{url}"\nkeepalive = {keepalive}\n'
        f'[topics]\nlayout = "home-assistant"\nnode = "{node}"\n'
        f'[[line]]\nport = "virtual"\ntimeout = 0.5\n{devices}'
    )
    return path


@dataclass
class BridgeProcess:
    """One `aiortu bridge` process; its stderr goes to `log`."""

    node: str
    process: subprocess.Popen[bytes]
    log: Path

    @classmethod
    def start(cls, node: str, config: Path) -> BridgeProcess:
        log = config.with_suffix(".log")
        with log.open("wb") as out:
            process = subprocess.Popen(
                [sys.executable, "-m", "aiortu", "bridge", "--config", str(config)],
                stdout=subprocess.DEVNULL, stderr=out,
            )  # fmt: skip
        return cls(node, process, log)

    def stop(self) -> dict[str, int]:
        """SIGTERM, wait, and the counts of its last line."""
        self.process.send_signal(signal.SIGTERM)
        self.process.wait(30)
        text = self.log.read_text()
        found = STOPPED.search(text)
        assert found is not None, text
        return {key: int(value) for key, value in found.groupdict().items()}

    def kill(self) -> None:
        self.process.kill()
        self.process.wait(10)
