"""A small asyncio client of the streaming server (:mod:`wearpose.stream.server`).

Example::

    async with StreamClient("ws://127.0.0.1:8765") as c:
        ready = await c.hello(Hello(0, names, ("position", "orientation"), 120.0, "binary"))
        await c.send_frame(FramePacket(0, seq, t, valid, data))
        ...
        final = await c.bye(0)          # every pose of subject 0 has arrived when this returns
    poses = c.poses                     # asyncio.Queue of (receive time, PosePacket)
"""

from __future__ import annotations

import asyncio
import json
import time
from collections import defaultdict, deque
from typing import Any, Callable

from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed, InvalidStatus

from wearpose.errors import WearposeError
from wearpose.stream.packets import (
    FramePacket,
    Hello,
    PacketError,
    PosePacket,
    decode_pose,
    encode_frame_binary,
    encode_frame_json,
)


class StreamError(WearposeError, RuntimeError):
    """The server refused a request (its ``error`` message), or the connection failed."""


class SubjectEnded(StreamError):
    """The server ended a subject this client was streaming (its ``bye`` notice: shutdown, ...)."""


#: Which reply an ``error`` answers, by its ``request`` field (an error without one answers a hello).
_REPLY_TO = {"hello": "ready", "bye": "bye", "stats": "stats", "subscribe": "subscribed"}


class StreamClient:
    """One WebSocket connection to the server.

    Args:
        url: ``ws://host:port``.
        on_pose: optional ``(receive_time, PosePacket) -> None`` called for each pose (receive
            time from ``time.perf_counter()``); without it poses go to :attr:`poses`.
        token: the server's access token (printed by ``wearpose serve``), sent as an
            ``Authorization: Bearer`` header; needed when the server requires it.
        origin: an ``Origin`` header to send (what a browser page would send; tests).
    """

    def __init__(self, url: str, on_pose: Callable[[float, PosePacket], None] | None = None, *,
                 token: str | None = None, origin: str | None = None) -> None:
        self.url = url
        self.on_pose = on_pose
        self.token, self.origin = token, origin
        self.poses: asyncio.Queue = asyncio.Queue()
        self.hellos: dict[int, Hello] = {}
        self.messages: deque = deque(maxlen=1000)  # control messages received (subject, error ...)
        #: Subjects the server ended (its ``bye`` message, with ``stats`` and ``reason``), by id.
        self.ended: dict[int, dict[str, Any]] = {}
        #: Poses the server dropped for this subscriber because it read too slowly (its reports).
        self.dropped_poses = 0
        self._ws: Any = None
        self._reader: asyncio.Task | None = None
        self._waiters: dict[tuple[str, Any], deque] = defaultdict(deque)

    async def connect(self) -> StreamClient:
        """Open the connection (StreamError naming the fix when the server refuses it)."""
        headers = {"Authorization": f"Bearer {self.token}"} if self.token else None
        try:
            self._ws = await connect(self.url, compression=None, max_size=1 << 22, ping_interval=None,
                                     origin=self.origin, additional_headers=headers)
        except InvalidStatus as exc:
            raise StreamError(_refusal_text(self.url, exc.response, self.token is not None)) from None
        self._reader = asyncio.create_task(self._read())
        return self

    @property
    def disconnected(self) -> bool:
        """True once the connection has ended (its reader task, which runs exactly as long as
        the WebSocket is open, is done); False before :meth:`connect` and while connected."""
        return self._reader is not None and self._reader.done()

    async def close(self) -> None:
        if self._ws is not None:
            await self._ws.close()
        if self._reader is not None:
            await asyncio.gather(self._reader, return_exceptions=True)

    async def __aenter__(self) -> StreamClient:
        return await self.connect()

    async def __aexit__(self, *exc: Any) -> None:
        await self.close()

    async def _read(self) -> None:
        try:
            async for msg in self._ws:
                t = time.perf_counter()
                try:
                    m = decode_pose(msg)
                except PacketError:  # not a message of the protocol: skipped
                    continue
                if isinstance(m, PosePacket):
                    if self.on_pose is not None:
                        self.on_pose(t, m)
                    else:
                        self.poses.put_nowait((t, m))
                    continue
                self.messages.append(m)
                kind = m.get("type")
                if kind == "bye":  # the end of a subject, asked for or not (server stopping ...)
                    self.ended[m.get("subject")] = m
                elif kind == "dropped":
                    self.dropped_poses += int(m.get("count") or 0)
                if kind == "error":
                    kind = _REPLY_TO.get(m.get("request") or "hello")
                key = (kind, None if kind in ("subscribed", "stats") else m.get("subject"))
                waiting = self._waiters.get(key)
                while waiting:
                    fut = waiting.popleft()
                    if not fut.done():  # a request that timed out left a cancelled future
                        fut.set_result(m)
                        break
        except ConnectionClosed:
            pass
        finally:
            for q in self._waiters.values():
                while q:
                    fut = q.popleft()
                    if not fut.done():
                        fut.set_exception(StreamError(f"connection to {self.url} closed"))

    async def _send(self, msg: str | bytes) -> None:
        """Send, or StreamError when the connection is gone (the server stopped or closed it)."""
        if self.disconnected:
            raise StreamError(f"connection to {self.url} closed{_close_text(self._ws)}")
        try:
            await self._ws.send(msg)
        except ConnectionClosed:
            raise StreamError(f"connection to {self.url} closed{_close_text(self._ws)}") from None

    async def _request(self, text: str, key: tuple[str, Any], timeout: float) -> dict[str, Any]:
        fut = asyncio.get_running_loop().create_future()
        self._waiters[key].append(fut)
        await self._send(text)
        return await asyncio.wait_for(fut, timeout)

    async def hello(self, hello: Hello, timeout: float = 120.0) -> dict[str, Any]:
        """Declare a subject; returns the server's ``ready`` message (StreamError if refused).
        ``timeout`` covers loading the estimator."""
        reply = await self._request(hello.to_json(), ("ready", hello.subject), timeout)
        if reply.get("type") == "error":
            raise StreamError(f"server refused subject {hello.subject}: {reply.get('error')}")
        self.hellos[hello.subject] = hello
        self.ended.pop(hello.subject, None)  # a restart: the bye of its previous stream came first
        return reply

    async def send_frame(self, pkt: FramePacket) -> None:
        """Send one frame in the subject's declared format; SubjectEnded once the server has
        ended the subject, StreamError when the connection is gone."""
        if pkt.subject in self.ended:
            raise SubjectEnded(f"subject {pkt.subject}: the server ended it "
                               f"({self.ended[pkt.subject].get('reason') or 'bye'})")
        h = self.hellos[pkt.subject]
        await self._send(encode_frame_binary(pkt) if h.format == "binary" else encode_frame_json(pkt, h.channels))

    async def send_raw(self, msg: str | bytes) -> None:
        """Send any message as is (fault injection, custom packets)."""
        await self._send(msg)

    async def bye(self, subject: int, timeout: float = 600.0) -> dict[str, Any]:
        """End a subject's stream; returns its final server stats once every pose was sent (at
        once when the server has already ended it). StreamError when the server refuses it."""
        if subject in self.ended:
            return self.ended[subject].get("stats", {})
        reply = await self._request(json.dumps({"type": "bye", "subject": subject}), ("bye", subject), timeout)
        if reply.get("type") == "error":
            raise StreamError(f"server refused bye for subject {subject}: {reply.get('error')}")
        return reply.get("stats", {})

    async def stats(self, timeout: float = 10.0) -> dict[str, Any]:
        return await self._request(json.dumps({"type": "stats"}), ("stats", None), timeout)

    async def subscribe(self, subjects: list[int] | None = None, fmt: str = "json",
                        timeout: float = 10.0) -> dict[str, Any]:
        """Receive the poses of ``subjects`` (None: all) published by other connections; returns
        the server's ``subscribed`` reply (its overload policy). StreamError when refused."""
        msg = json.dumps({"type": "subscribe", "subjects": subjects, "format": fmt})
        reply = await self._request(msg, ("subscribed", None), timeout)
        if reply.get("type") == "error":
            raise StreamError(f"server refused the subscription: {reply.get('error')}")
        return reply


def _close_text(ws: Any) -> str:
    code = getattr(ws, "close_code", None)
    return f" (code {code}: {getattr(ws, 'close_reason', None) or 'no reason given'})" if code is not None else ""


def _refusal_text(url: str, response: Any, had_token: bool) -> str:
    """What a refused handshake means and what to do (the server's own text included)."""
    body = (response.body or b"").decode("utf-8", "replace").strip()
    if response.status_code == 401:
        fix = ("the token given is not the server's" if had_token else
               "this server requires its access token: pass --token (printed by `wearpose serve` at start-up)")
        return f"{url}: HTTP 401, {fix}. Server: {body}"
    if response.status_code == 403:
        return f"{url}: HTTP 403, the server refuses this client ({body})"
    return f"{url}: HTTP {response.status_code}, the server refused the connection ({body})"
