"""The bridge's connection to its broker: connect with the last will, send the outbox in
order, take the commands, keep the connection alive, and connect again when it drops.

A QoS 1 message leaves the [`Outbox`][aiortu.bridge.Outbox] for the in-flight window
when it is written and is forgotten only when the broker acknowledges it; the messages in
flight when the connection drops go back to the front of the outbox, so the order holds and
nothing is lost but what the outbox's bound drops (a broker may then get a message twice:
QoS 1 is at least once). After each connection the session first sends what
`on_connect` returns (availability, discovery, Sparkplug births), then the backlog.

On asyncio the connection is pushed (`_session_push.py`): the broker's packets are read in
the event loop's read callback and the outbox is written from the call that fills it, so a
poll's messages and their acknowledgements wake no task; on trio a task reads anyio's stream
and another sends. Both paths make the same packets, in the same order, with the same
functions.
"""

from __future__ import annotations

import contextlib
import ssl
from collections.abc import Callable
from dataclasses import dataclass

import anyio
import anyio.abc

from aiortu._log import get_logger
from aiortu.bridge._broker import Broker, BrokerError
from aiortu.bridge._outbox import Message, Outbox
from aiortu.bridge._packets import (
    PUBACK_SIZE,
    ConnectRefused,
    Packet,
    PacketReader,
    PacketType,
    Publish,
    PublishWriter,
    connect_packet,
    disconnect_packet,
    pingreq_packet,
    puback_packet,
    subscribe_packet,
)
from aiortu.bridge._session_push import PushedLink, open_pushed, push_session

__all__ = ("BrokerSession", "SessionHooks")

_LINK_ERRORS = (
    OSError, TimeoutError, anyio.BrokenResourceError, anyio.EndOfStream,
    anyio.ClosedResourceError, ValueError, BrokerError,
)  # fmt: skip
"""What ends a connection and calls for the next one (a ValueError: bytes that are not MQTT)."""


def _link_failure(error: Exception) -> Exception | None:
    """The connection failure `error` is (or holds, alone, in a group), else None."""
    if isinstance(error, _LINK_ERRORS):
        return error
    if isinstance(error, ExceptionGroup):
        matched, rest = error.split(_LINK_ERRORS)
        if rest is None and matched is not None:
            leaf: Exception = matched
            while isinstance(leaf, ExceptionGroup):
                leaf = leaf.exceptions[0]
            return leaf
    return None


_log = get_logger(__name__)

_FATAL = (1, 2, 4, 5)
"""CONNACK refusals that trying again will not cure: protocol, client id, login."""


@dataclass(slots=True)
class SessionHooks:
    """What the bridge tells the session: the last `will` of each connection (made anew for
    each: Sparkplug's bdSeq counts connections), the `subscriptions`, the messages to send
    first after connecting (`on_connect`), how to encode a message that carries `metrics`
    when it is sent (`prepare`: its Sparkplug sequence number; any other goes as made), and
    where received messages go (`on_publish`, which must not block, and on asyncio is called
    from the event loop's read callback, where no task runs: anyio's functions that ask which
    backend runs, such as `anyio.current_time`, fail there)."""

    will: Callable[[], Message | None]
    subscriptions: Callable[[], list[str]]
    on_connect: Callable[[], list[Message]]
    on_publish: Callable[[Publish], None]
    prepare: Callable[[Message], bytes] = lambda message: message.payload


class BrokerSession:
    """Keeps the bridge connected to `broker`, delivering `outbox` (see the module
    docstring). `window` QoS 1 messages may wait for their acknowledgement at once; the
    waits between connection attempts double from `reconnect_delay[0]` to
    `reconnect_delay[1]` seconds."""

    def __init__(
        self,
        broker: Broker,
        outbox: Outbox,
        hooks: SessionHooks,
        *,
        window: int = 256,
        reconnect_delay: tuple[float, float] = (0.1, 5.0),
        connect_timeout: float = 5.0,
    ) -> None:
        self.broker = broker
        self.outbox = outbox
        self.hooks = hooks
        self.window = window
        self.reconnect_delay = reconnect_delay
        self.connect_timeout = connect_timeout
        self.connected = False
        """Whether the session is connected now."""
        self.connections = 0
        """Connections made (the first one counts)."""
        self._delivered = 0
        self.last_error: str | None = None
        """Why the last connection failed or ended."""
        self._inflight: dict[int, Message] = {}
        self._next_id = 0
        self._stream: anyio.abc.ByteStream | PushedLink | None = None
        self._link: PushedLink | None = None  # while a pushed connection is served
        self._holding = False  # while a pushed chunk is read: write after it
        self._pinged = False  # a PINGREQ went, and the broker has said nothing since
        self._acked: anyio.Event | None = None
        self._heard = 0
        self._reader = PacketReader()
        self._writer = PublishWriter()
        self._early: list[Packet] = []
        self._sending = anyio.Lock()

    @property
    def delivered(self) -> int:
        """Messages the broker took: acknowledged (QoS 1) or written (QoS 0). On a pushed
        connection the acknowledgements waiting in the kernel are taken first."""
        self._collect()
        return self._delivered

    async def _write(self, stream: anyio.abc.ByteStream | PushedLink, data: bytes) -> None:
        # The sender, the pinger and the acknowledgements of commands share the stream. The
        # lock is taken without a checkpoint when free (the usual case): the send has one.
        sending = self._sending
        try:
            sending.acquire_nowait()
        except anyio.WouldBlock:
            await sending.acquire()
        try:
            await stream.send(data)
        finally:
            sending.release()

    async def connect(self) -> None:
        """Connect once: raise [`BrokerError`][aiortu.bridge.BrokerError] if the broker
        refuses the login or its certificate does not check, OSError (or TimeoutError) if it
        cannot be reached; either is kept in `last_error`."""
        try:
            self._stream = await self._open()
        except (OSError, BrokerError) as error:
            self.last_error = str(error) or type(error).__name__
            raise

    async def run(self) -> None:
        """Deliver until cancelled, connecting again (with back-off) whenever the connection
        fails; an open connection from [`connect`][aiortu.bridge.BrokerSession.connect] is used
        first."""
        delay = self.reconnect_delay[0]
        while True:
            try:
                if self._stream is None:
                    self._stream = await self._open()
                delay = self.reconnect_delay[0]
                await self._serve(self._stream)
            except Exception as error:  # a group, from the connection's tasks
                failure = _link_failure(error)
                if failure is None:
                    raise
                self.last_error = str(failure) or type(failure).__name__
                _log.warning("broker %s: %s; connecting again in %.1f s",
                             self.broker.url, self.last_error, delay)  # fmt: skip
            finally:
                await self._drop()
            await anyio.sleep(delay)
            delay = min(delay * 2, self.reconnect_delay[1])

    async def close(self) -> None:
        """Say goodbye to the broker (DISCONNECT: no last will) and close the connection."""
        stream, self._stream = self._stream, None
        if stream is None:
            return
        with anyio.move_on_after(1, shield=True):
            with contextlib.suppress(OSError, anyio.BrokenResourceError, anyio.ClosedResourceError,
                                     anyio.EndOfStream):  # fmt: skip
                await stream.send(disconnect_packet())
            await stream.aclose()

    async def _open(self) -> anyio.abc.ByteStream | PushedLink:
        broker = self.broker
        will = self.hooks.will()
        with anyio.fail_after(self.connect_timeout):
            context = broker.ssl_context()
            stream: anyio.abc.ByteStream | PushedLink
            try:
                if push_session():
                    stream = await open_pushed(broker.host, broker.port, context)
                elif context is None:
                    stream = await anyio.connect_tcp(broker.host, broker.port)
                else:
                    stream = await anyio.connect_tcp(
                        broker.host, broker.port, ssl_context=context,
                        tls_standard_compatible=False,
                    )  # fmt: skip
            except ssl.SSLError as error:
                # A certificate that does not check is the configuration's fault.
                reason = getattr(error, "verify_message", None) or error.reason or error
                raise BrokerError(f"broker {broker.url}: TLS failed: {reason}") from None
            try:
                await stream.send(connect_packet(
                    broker.client_id, keepalive=broker.keepalive, username=broker.username,
                    password=broker.password,
                    will=None if will is None else (will.topic, will.payload, will.qos,
                                                    will.retain),
                ))  # fmt: skip
                await self._connack(stream)
            except BaseException:
                await _abort(stream)
                raise
        self.connections += 1
        self.connected = True
        _log.info("connected to broker %s", broker.url)
        return stream

    async def _connack(self, stream: anyio.abc.ByteStream | PushedLink) -> None:
        reader = PacketReader()
        while True:
            packets = reader.feed(await stream.receive())
            if packets:
                break
        first = packets[0]
        if first.type != PacketType.CONNACK or len(first.body) != 2:
            raise OSError("the broker did not answer CONNECT with CONNACK")
        if first.body[1]:
            refused = ConnectRefused(first.body[1])
            message = f"broker {self.broker.url}: {refused}"
            if first.body[1] in _FATAL:
                raise BrokerError(message)
            raise OSError(message)
        self._reader = reader
        self._early = packets[1:]  # what came with the CONNACK, handled once serving

    async def _serve(self, stream: anyio.abc.ByteStream | PushedLink) -> None:
        topics = self.hooks.subscriptions()
        if topics:
            await self._write(stream, subscribe_packet(self._packet_id(), [(t, 1) for t in topics]))
        first = self.hooks.on_connect()
        if first:
            await self._write(stream, self._encode(first))
        async with anyio.create_task_group() as tasks:
            tasks.start_soon(self._ping, stream)
            if isinstance(stream, PushedLink):
                await self._push(stream)
            else:
                tasks.start_soon(self._receive, stream)
                await self._deliver(stream)

    async def _deliver(self, stream: anyio.abc.ByteStream) -> None:
        """Send the outbox in order, within the window, as it fills: a task's way."""
        while True:
            await self.outbox.wait()
            while len(self._inflight) >= self.window:
                self._acked = anyio.Event()
                await self._acked.wait()
                self._acked = None
            await self._write(stream, self._encode(self.outbox.take(self._room())))

    def _room(self) -> int:
        return self.window - len(self._inflight)

    def _encode(self, messages: list[Message]) -> bytes:
        """The PUBLISH packets of `messages`, each QoS 1 one in flight from now on."""
        writer = self._writer
        try:
            writer.add_all(messages, self._number(messages), self.hooks.prepare)
        finally:
            packets = writer.joined()  # and none left for the next batch if one failed
        return packets

    def _number(self, messages: list[Message]) -> list[int]:
        """The packet id of each of `messages` (0 at QoS 0): the next one not in flight."""
        inflight, ids = self._inflight, []
        number = self._next_id
        for message in messages:
            if message.qos:
                number = number % 65535 + 1
                if number in inflight:
                    self._next_id = number
                    number = self._packet_id()
                inflight[number] = message
                ids.append(number)
            else:
                ids.append(0)
        self._next_id = number
        self._delivered += ids.count(0)  # QoS 0: taken once written
        return ids

    async def _receive(self, stream: anyio.abc.ByteStream) -> None:
        answers = self._answers(self._early_packets())
        while True:
            if answers:
                await self._write(stream, answers)
            answers = self._read(await stream.receive())

    async def _push(self, link: PushedLink) -> None:
        """Serve a pushed connection: read in the loop's callback, write when the outbox is
        filled, an acknowledgement makes room or the transport drains; until it ends."""
        self._link = link
        try:
            link.write(self._answers(self._early_packets()))
            link.on_writable = self._flush
            self.outbox.notify(self._filled)
            link.set_receiver(self._pushed)
            self._flush()
            await link.ended()
        finally:
            self._collect()  # what the broker acknowledged is not sent again
            self.outbox.notify(None)
            self._link = link.on_writable = None

    def _pushed(self, data: bytes) -> None:
        """The pushed connection's read callback: `_receive`'s work, with what a command puts
        in the outbox written after its PUBACK, as the sending task would."""
        self._holding = True
        try:
            answers = self._read(data)
        finally:
            self._holding = False
        if answers and self._link is not None:
            self._link.write(answers)
        self._flush()

    def _filled(self) -> None:
        """The outbox's listener: the acknowledgements waiting in the kernel first (read in
        this turn of the loop, not in a wake of their own), then the writes. A command's
        messages wait for its PUBACK: the read callback writes them after it."""
        if not self._holding:
            self._collect()
            self._flush()

    def _collect(self) -> None:
        """Take what the pushed link holds below its mark (see `PushedLink.collect`)."""
        if self._link is not None:
            self._link.collect()

    def _flush(self) -> None:
        """Write what waits in the outbox, within the window, while the link takes it."""
        link, outbox = self._link, self.outbox
        if link is None:
            return
        while link.writable and outbox and (room := self._room()) > 0:
            link.write(self._encode(outbox.take(room)))
        # Never woken by the PUBACKs of what is in flight alone (the next write collects
        # them), but by any byte more; by any byte while messages wait for room (each PUBACK
        # makes some) and after a PINGREQ (the keep-alive hears the broker as it did).
        owed = PUBACK_SIZE * len(self._inflight) - self._reader.pending
        link.expect(1 if self._pinged or outbox else owed + 1)

    def _early_packets(self) -> list[Packet]:
        """What came with the CONNACK (kept until the connection is served)."""
        early, self._early = self._early, []
        return early

    def _read(self, data: bytes) -> bytes:
        """Take `data` from the broker: the bulk, acknowledgements alone, without a packet
        each; return the answers to write."""
        self._heard += 1
        self._pinged = False
        acknowledged = self._reader.acknowledgements(data)
        if acknowledged is not None:
            self._acknowledged(acknowledged)
            return b""
        return self._answers(self._reader.feed(data))

    def _answers(self, packets: list[Packet]) -> bytes:
        """Take `packets` from the broker; return the answers to write (the PUBACKs of
        commands), in order, in one piece."""
        return b"".join([reply for packet in packets if (reply := self._handle(packet))])

    def _acknowledged(self, packet_ids: tuple[int, ...]) -> None:
        inflight = self._inflight
        before, pop = len(inflight), inflight.pop
        for packet_id in packet_ids:
            pop(packet_id, None)
        self._delivered += before - len(inflight)  # not done.count(None): Message's __eq__ each
        if self._acked is not None:
            self._acked.set()

    def _handle(self, packet: Packet) -> bytes | None:
        """Take `packet` from the broker; return what to answer (a PUBLISH's PUBACK)."""
        if packet.type == PacketType.PUBACK:
            self._acknowledged((int.from_bytes(packet.body[:2], "big"),))
        elif packet.type == PacketType.PUBLISH:
            publish = Publish.parse(packet)
            self.hooks.on_publish(publish)
            if publish.qos == 1 and publish.packet_id is not None:
                return puback_packet(publish.packet_id)
        elif packet.type == PacketType.SUBACK and 0x80 in packet.body[2:]:
            _log.warning("broker %s refused a subscription: commands may not arrive",
                         self.broker.url)  # fmt: skip
        return None

    async def _ping(self, stream: anyio.abc.ByteStream | PushedLink) -> None:
        """A PINGREQ every half keep-alive. The broker answers each at once, so a link that
        stays silent for two of them (a keep-alive) is dead: found within 1.5 keep-alives,
        and no timer is set for each receive."""
        heard, silent = self._heard, 0
        while True:
            await anyio.sleep(self.broker.keepalive / 2)
            if self._heard != heard:
                heard, silent = self._heard, 0
            else:
                silent += 1
                if silent >= 2:
                    raise TimeoutError(f"the broker said nothing in {self.broker.keepalive} s")
            self._pinged = True
            self._flush()  # a pushed link: woken by the PINGRESP, whatever else it waits for
            await self._write(stream, pingreq_packet())

    def _packet_id(self) -> int:
        for _ in range(65535):
            self._next_id = self._next_id % 65535 + 1
            if self._next_id not in self._inflight:
                return self._next_id
        raise OSError("every MQTT packet id is in flight")

    async def _drop(self) -> None:
        """The connection ended: its unacknowledged messages go back first, in order."""
        self.connected = self._pinged = False
        stream, self._stream = self._stream, None
        if stream is not None:
            await _abort(stream)
        self.outbox.put_back(self._inflight.values())  # a dict keeps the order they were sent
        self._inflight.clear()
        if self._acked is not None:
            self._acked.set()


async def _abort(stream: anyio.abc.ByteStream | PushedLink) -> None:
    """Close `stream` at once."""
    if isinstance(stream, PushedLink):
        stream.abort()
    else:
        await anyio.aclose_forcefully(stream)
