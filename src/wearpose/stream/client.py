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


class StreamClient:
    """One WebSocket connection to the server.

    Args:
        url: ``ws://host:port``.
        on_pose: optional ``(receive_time, PosePacket) -> None`` called for each pose (receive
            time from ``time.perf_counter()``); without it poses go to :attr:`poses`.
    """

    def __init__(self, url: str, on_pose: Callable[[float, PosePacket], None] | None = None) -> None:
        self.url = url
        self.on_pose = on_pose
        self.poses: asyncio.Queue = asyncio.Queue()
        self.hellos: dict[int, Hello] = {}
        self.messages: deque = deque(maxlen=1000)  # control messages received (subject, error ...)
        self._ws: Any = None
        self._reader: asyncio.Task | None = None
        self._waiters: dict[tuple[str, Any], deque] = defaultdict(deque)

    async def connect(self) -> StreamClient:
        from websockets.asyncio.client import connect

        self._ws = await connect(self.url, compression=None, max_size=1 << 22, ping_interval=None)
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
        from websockets.exceptions import ConnectionClosed

        try:
            async for msg in self._ws:
                t = time.perf_counter()
                try:
                    m = decode_pose(msg)
                except (PacketError, json.JSONDecodeError):
                    continue
                if isinstance(m, PosePacket):
                    if self.on_pose is not None:
                        self.on_pose(t, m)
                    else:
                        self.poses.put_nowait((t, m))
                    continue
                self.messages.append(m)
                kind = m.get("type")
                key = (("ready" if kind == "error" else kind), m.get("subject"))  # an error answers a hello
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

    async def _request(self, text: str, key: tuple[str, Any], timeout: float) -> dict[str, Any]:
        fut = asyncio.get_running_loop().create_future()
        self._waiters[key].append(fut)
        await self._ws.send(text)
        return await asyncio.wait_for(fut, timeout)

    async def hello(self, hello: Hello, timeout: float = 120.0) -> dict[str, Any]:
        """Declare a subject; returns the server's ``ready`` message (StreamError if refused).
        ``timeout`` covers loading the estimator."""
        reply = await self._request(hello.to_json(), ("ready", hello.subject), timeout)
        if reply.get("type") == "error":
            raise StreamError(f"server refused subject {hello.subject}: {reply.get('error')}")
        self.hellos[hello.subject] = hello
        return reply

    async def send_frame(self, pkt: FramePacket) -> None:
        """Send one frame in the subject's declared format."""
        h = self.hellos[pkt.subject]
        await self._ws.send(encode_frame_binary(pkt) if h.format == "binary" else encode_frame_json(pkt, h.channels))

    async def send_raw(self, msg: str | bytes) -> None:
        """Send any message as is (fault injection, custom packets)."""
        await self._ws.send(msg)

    async def bye(self, subject: int, timeout: float = 600.0) -> dict[str, Any]:
        """End a subject's stream; returns its final server stats once every pose was sent."""
        reply = await self._request(json.dumps({"type": "bye", "subject": subject}), ("bye", subject), timeout)
        return reply.get("stats", {})

    async def stats(self, timeout: float = 10.0) -> dict[str, Any]:
        return await self._request(json.dumps({"type": "stats"}), ("stats", None), timeout)

    async def subscribe(self, subjects: list[int] | None = None, fmt: str = "json") -> None:
        """Receive the poses of ``subjects`` (None: all) published by other connections."""
        await self._ws.send(json.dumps({"type": "subscribe", "subjects": subjects, "format": fmt}))
