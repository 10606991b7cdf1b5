"""Where the broker is and how to log in: `mqtt://` or `mqtts://` URLs, certificates,
user name and password.

[`parse_broker_url`][aiortu.bridge.parse_broker_url] turns `mqtt://user:password@host:1883`
into a [`Broker`][aiortu.bridge.Broker]; a URL it cannot use raises
[`BrokerError`][aiortu.bridge.BrokerError] with one sentence saying why.
"""

from __future__ import annotations

import ssl
import urllib.parse
from dataclasses import dataclass

from aiortu.bridge._packets import MAX_STRING_BYTES

__all__ = ("Broker", "BrokerError", "parse_broker_url")

_PORTS = {"mqtt": 1883, "mqtts": 8883}


class BrokerError(Exception):
    """The broker cannot be used as configured: a bad URL, certificate, or a refused login.
    The message is one sentence."""


@dataclass(frozen=True, slots=True)
class Broker:
    """An MQTT broker: `host` and `port`, `tls` for `mqtts://` (with the CA file `ca_file`,
    or the system's, and a client certificate `cert_file` and `key_file` if given; `insecure`
    skips the check of the broker's certificate, for tests only),
    `username` and `password`, the `client_id` the bridge connects as and the `keepalive` in
    seconds (the broker publishes the bridge's last will after 1.5 times that of silence)."""

    host: str
    port: int
    tls: bool = False
    username: str | None = None
    password: str | None = None
    client_id: str = "aiortu-bridge"
    keepalive: int = 30
    ca_file: str | None = None
    cert_file: str | None = None
    key_file: str | None = None
    insecure: bool = False

    @property
    def url(self) -> str:
        """The broker's URL, without the password."""
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{'mqtts' if self.tls else 'mqtt'}://{host}:{self.port}"

    def ssl_context(self) -> ssl.SSLContext | None:
        """The TLS context of an `mqtts://` broker (None for `mqtt://`)."""
        if not self.tls:
            return None
        try:
            context = ssl.create_default_context(cafile=self.ca_file)
            if self.cert_file is not None:
                context.load_cert_chain(self.cert_file, self.key_file)
        except (OSError, ssl.SSLError) as error:
            raise BrokerError(f"the broker's certificates cannot be loaded: {error}") from None
        if self.insecure:
            context.check_hostname = False
            context.verify_mode = ssl.CERT_NONE
        return context


def parse_broker_url(url: str, **options: object) -> Broker:
    """The [`Broker`][aiortu.bridge.Broker] at `url` (`mqtt://[user[:password]@]host[:port]`
    or `mqtts://...`); `options` are its other fields (a user name or password in `options`
    wins over one in the URL)."""
    parts = urllib.parse.urlsplit(url)
    if parts.scheme not in _PORTS:
        raise BrokerError(f"broker URL {url!r}: the scheme must be mqtt:// or mqtts://")
    try:
        port = parts.port
    except ValueError:
        raise BrokerError(f"broker URL {url!r}: the port must be a number 1..65535") from None
    if not parts.hostname:
        raise BrokerError(f"broker URL {url!r}: names no host")
    if parts.path not in ("", "/") or parts.query or parts.fragment:
        raise BrokerError(f"broker URL {url!r}: has more than a host and port")
    fields: dict[str, object] = {
        "username": urllib.parse.unquote(parts.username) if parts.username else None,
        "password": urllib.parse.unquote(parts.password) if parts.password else None,
    }
    fields.update({k: v for k, v in options.items() if v is not None})
    for key in ("client_id", "username", "password"):
        value = fields.get(key)
        if isinstance(value, str) and (size := len(value.encode())) > MAX_STRING_BYTES:
            name = key.replace("_", " ")
            raise BrokerError(
                f"broker {name}: {size:,} bytes, more than the {MAX_STRING_BYTES:,} MQTT allows"
            )
    keepalive = fields.get("keepalive", 30)
    if isinstance(keepalive, bool) or not isinstance(keepalive, int) or not 1 <= keepalive <= 65535:
        raise BrokerError(f"broker keepalive {keepalive!r}: must be whole seconds 1..65535")
    try:
        return Broker(
            parts.hostname,
            port or _PORTS[parts.scheme],
            tls=parts.scheme == "mqtts",
            **fields,  # type: ignore[arg-type]
        )
    except TypeError as error:
        raise BrokerError(f"broker options: {error}") from None
