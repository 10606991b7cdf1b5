"""A bridge's lines on every transport: a `tls://` line with its certificate files (relative to
the configuration) polled through a Modbus/TCP Security server, `framing = "ascii"`, and each
mistake in a line's transport one line naming its key."""

from __future__ import annotations

from pathlib import Path

import pytest

import aiortu
from aiortu.bridge import Bridge, load_config, parse_config
from aiortu.core.model import load_profile
from aiortu.errors import ConfigError
from aiortu.slave import ProfileStore
from aiortu.transport import AccessRule, RoleRules
from tests.bridge.helpers import HEAT_PUMP
from tests.bridge.test_bridge_broker import until
from tests.transport.certificates import Authority

pytestmark = pytest.mark.timeout(60)

NO_BROKER = "mqtt://127.0.0.1:1"
"""Nothing listens there: the bridge polls and keeps its messages for a broker to come."""


def _site(port: str, line: str = "") -> str:
    return (
        f'[broker]\nurl = "{NO_BROKER}"\n[[line]]\nport = "{port}"\ntimeout = 1.0\n{line}\n'
        f'[[line.device]]\nname = "hp"\nunit = 1\nprofile = "{HEAT_PUMP}"\n'
    )


async def test_a_tls_line_is_polled_with_the_files_the_configuration_names(
    tmp_path: Path,
) -> None:
    ca = Authority(tmp_path)
    server, client = ca.issue("server", server=True), ca.issue("bridge", role="poller")
    rules = RoleRules({"poller": AccessRule(frozenset({1, 2, 3, 4}), read_only=True)})
    store = ProfileStore(load_profile(HEAT_PUMP))
    files = {"certfile": server.certfile, "keyfile": server.keyfile, "cafile": ca.cafile}
    async with aiortu.serve("tls://127.0.0.1:0", {1: store}, rules=rules, **files) as served:
        site = tmp_path / "site.toml"
        files = (f'cert_file = "{client.certfile.name}"\nkey_file = "{client.keyfile.name}"\n'
                 f'ca_file = "{ca.cafile.name}"\n')  # fmt: skip
        site.write_text(_site(f"tls://127.0.0.1:{served.port}", files), encoding="utf-8")
        config = load_config(site)
        assert config.lines[0].options["cafile"] == str(ca.cafile)
        async with Bridge(config) as bridge:
            await until(
                lambda: bridge.stats.readings >= len(config.lines[0].devices[0].profile.points)
            )
        assert served.denied == 0


def test_an_ascii_line_asks_the_master_for_ascii() -> None:
    config = parse_config(_site("rtu+tcp://10.0.0.5:4001", 'framing = "ascii"'), "site.toml")
    assert config.lines[0].options["framing"] == "ascii"


@pytest.mark.parametrize(
    ("port", "line", "message"),
    [
        ("tls://10.0.0.5:802", 'cert_file = "c.pem"\nkey_file = "k.pem"',
         "line[0].ca_file: is required for a tls:// port (Modbus/TCP Security)"),
        ("tcp://10.0.0.5:502", 'cert_file = "c.pem"',
         "line[0].cert_file: is for a tls:// port only"),
        ("tls://10.0.0.5:802", 'cert_file = "c.pem"\nkey_file = "k.pem"\nca_file = "ca.pem"',
         "line[0].cert_file: no such file: c.pem"),
        ("tls://10.0.0.5:802", 'cert_file = 1\nkey_file = "k.pem"\nca_file = "ca.pem"',
         "line[0].cert_file: must be a file name, not 1"),
        ("tcp://10.0.0.5:502", 'framing = "ascii"',
         'line[0].framing: "ascii" is for a serial port or rtu+tcp://'),
        ("virtual", 'framing = "ascii"',
         'line[0].framing: "ascii" is for a serial port or rtu+tcp://'),
        ("/dev/ttyUSB0", 'framing = "asci"',
         "line[0].framing: must be \"rtu\" or \"ascii\", not 'asci'"),
    ],
)  # fmt: skip
def test_a_line_transport_mistake_is_one_line(port: str, line: str, message: str) -> None:
    with pytest.raises(ConfigError) as caught:
        parse_config(_site(port, line), "site.toml")
    assert str(caught.value) == f"site.toml: {message}"
