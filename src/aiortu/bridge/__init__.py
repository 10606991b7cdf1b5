"""The MQTT bridge: a line's devices, described by profiles, published to an MQTT broker
(plain topics, Home Assistant discovery or Sparkplug B), with writes back from it.

[`Bridge`][aiortu.bridge.Bridge] runs a [`BridgeConfig`][aiortu.bridge.BridgeConfig]
([`load_config`][aiortu.bridge.load_config] reads one from TOML); `aiortu bridge --config
FILE` does the same from the command line. The bridge speaks MQTT 3.1.1 itself and encodes
Sparkplug B's protobuf payloads itself: it needs no package beyond aiortu's. See
`docs/bridge.md`.
"""

from __future__ import annotations

from aiortu._public import publish
from aiortu.bridge._bridge import Bridge, BridgeStats, run
from aiortu.bridge._broker import Broker, BrokerError, parse_broker_url
from aiortu.bridge._config import (
    LAYOUTS,
    VIRTUAL_PORT,
    BridgeConfig,
    DeviceConfig,
    LineConfig,
    TopicLayout,
)
from aiortu.bridge._config_file import load_config, parse_config
from aiortu.bridge._outbox import Message, Outbox
from aiortu.bridge._payloads import CommandError, format_value, parse_command
from aiortu.bridge._protobuf import (
    DataType,
    Metric,
    SparkplugPayload,
    decode_payload,
    encode_payload,
)
from aiortu.bridge._session import BrokerSession, SessionHooks
from aiortu.bridge._state import Command, DeviceState, Layout
from aiortu.bridge._topics import LayoutTopic
from aiortu.core.model import shipped_profiles

__all__ = (
    "LAYOUTS",
    "VIRTUAL_PORT",
    "Bridge",
    "BridgeConfig",
    "BridgeStats",
    "Broker",
    "BrokerError",
    "BrokerSession",
    "Command",
    "CommandError",
    "DataType",
    "DeviceConfig",
    "DeviceState",
    "Layout",
    "LayoutTopic",
    "LineConfig",
    "Message",
    "Metric",
    "Outbox",
    "SessionHooks",
    "SparkplugPayload",
    "TopicLayout",
    "decode_payload",
    "encode_payload",
    "format_value",
    "load_config",
    "parse_broker_url",
    "parse_command",
    "parse_config",
    "run",
    "shipped_profiles",
)

publish(__name__, __all__, globals())
