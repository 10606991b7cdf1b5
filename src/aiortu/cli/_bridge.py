"""`aiortu bridge`: publish the devices of one or more lines to an MQTT broker.

Reads the bridge's TOML file (lines, devices and their profiles, broker, topic layout; see
`docs/bridge.md`), connects to the broker, opens the lines and polls until SIGINT or SIGTERM
(exit 0). A broker that cannot be reached is waited for while the bridge polls and buffers.
A bad file is one line naming the file, the key and the problem (exit 2); a broker URL,
certificate or login the broker refuses, a topic, client id, user name or password longer than
MQTT allows, or a line that cannot be opened, one line (exit 1).
"""

from __future__ import annotations

import argparse
import signal
import sys

import anyio

from aiortu.cli import SUMMARIES, CommandFailed, Subparsers
from aiortu.cli._arguments import plural
from aiortu.cli._messages import library_warnings_on_stderr, port_failure
from aiortu.errors import ConfigError, PortError

__all__ = ("register", "run")

_EXAMPLES = """\
examples:
  aiortu bridge --config bridge.toml
      poll the lines of the file and publish to its broker
  aiortu bridge --config examples/bridge/demo.toml
      three simulated devices (a virtual line) to a broker on localhost:1883

exit codes: 0 stopped by Ctrl-C (SIGINT) or SIGTERM; 1 the broker refused the URL, the
certificates or the login, a topic or login is longer than MQTT allows, or a line cannot be
opened; 2 a bad configuration file"""


def register(subparsers: Subparsers) -> None:
    """Add the `bridge` subcommand to `subparsers`."""
    parser = subparsers.add_parser(
        "bridge",
        help=SUMMARIES["bridge"],
        description="Publish the devices of Modbus lines to an MQTT broker (plain topics, Home "
        "Assistant discovery or Sparkplug B) and write back what the broker sends.",
        epilog=_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--config", required=True, metavar="FILE", help="the bridge's TOML file")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Run the bridge of `args.config` until SIGINT or SIGTERM."""
    from aiortu.bridge import BrokerError, load_config

    try:
        config = load_config(args.config)
    except ConfigError as error:
        print(f"aiortu bridge: error: {error}", file=sys.stderr)
        return 2
    except BrokerError as error:
        raise CommandFailed(str(error)) from None
    with library_warnings_on_stderr("bridge"):
        return anyio.run(_serve, config)


async def _serve(config: object) -> int:
    from aiortu.bridge import Bridge, BridgeConfig, BrokerError

    assert isinstance(config, BridgeConfig)
    failure: CommandFailed | None = None
    with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
        try:
            async with Bridge(config) as bridge:
                devices = plural(len(bridge.devices), "device")
                print(f"aiortu bridge: {devices} on {plural(len(config.lines), 'line')} to "
                      f"{config.broker.url} ({config.topics.layout}); Ctrl-C to stop",
                      file=sys.stderr)  # fmt: skip
                async for _ in signals:
                    break
                stats = bridge.stats
                print(f"aiortu bridge: stopped: {stats.values} values in {stats.messages} "
                      f"messages, {bridge.session.delivered} delivered, {bridge.outbox.dropped} "
                      f"dropped, {len(bridge.outbox)} waiting", file=sys.stderr)  # fmt: skip
        except BrokerError as error:
            failure = CommandFailed(str(error))
        except PortError as error:
            failure = CommandFailed(port_failure(error))
    # Raised out here, not from inside the bridge's task group.
    if failure is not None:
        raise failure
    return 0
