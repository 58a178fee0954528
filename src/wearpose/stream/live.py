"""Live device inputs feeding the streaming server in-process (``wearpose serve --input NAME``).

An :class:`InputBridge` opens its :class:`~wearpose.stream.inputs.LiveInput`, declares the
input's sensors as a subject (the same ``hello`` path as a WebSocket device: estimator, stride,
warm-up, refusal when a needed sensor is missing), converts each device frame to canonical
channels (:func:`~wearpose.stream.inputs.canonical_frame`: the recording format's one
conversion path) and hands it to the server's reorder buffer. Protocol violations are counted in
the server's ``malformed_total`` and the subject's ``malformed``; a missing sensor is masked.
The subject's poses go where every pose goes: subscribers (``view-live``) and ``--output``s.
"""

from __future__ import annotations

import json
import logging
from typing import Any

from wearpose.stream.inputs.base import DeviceFrame, LiveInput, canonical_channels, canonical_frame
from wearpose.stream.inputs.mvn import SEGMENTS, MvnPoseEstimator, pose_frame, segment_info
from wearpose.stream.packets import FramePacket, Hello, PacketError

log = logging.getLogger("wearpose.stream")


class _LocalPeer:
    """The owner of an input's subject: receives its control replies and (ignores) its poses."""

    def __init__(self, name: str) -> None:
        self.remote_address = f"input:{name}"
        self.last_control: dict[str, Any] | None = None
        self.poses = 0

    async def send(self, msg: str | bytes) -> None:
        if isinstance(msg, str):
            d = json.loads(msg)
            if d.get("type") == "pose":
                self.poses += 1
            else:
                self.last_control = d
        else:
            self.poses += 1


class InputBridge:
    """One live input -> one subject of ``server`` (module doc).

    Args:
        server: a started :class:`~wearpose.stream.StreamServer`.
        source: the input (not yet opened).
        subject: its subject id.
        subject_info: ``Recording.subject``-style facts for the estimator (e.g. EM-POSE offsets).
    """

    def __init__(self, server: Any, source: LiveInput, subject: int = 0, subject_info: dict[str, Any] | None = None) -> None:
        self.server, self.source, self.subject = server, source, subject
        self.subject_info = dict(subject_info or {})
        self.peer = _LocalPeer(source.name)
        self.ready: dict[str, Any] | None = None
        self._early: list[Any] = []  # frames (and protocol violations) before the subject was open, in order
        self.channels: tuple[str, ...] = ()
        self.counts = {"frames": 0, "converted_malformed": 0, "early": 0}

    async def start(self) -> dict[str, Any]:
        """Open the input and the subject; returns the server's ``ready`` reply (StreamError when refused)."""
        self.source.attach(self._frame, self._malformed)
        await self.source.open()
        self.channels = canonical_channels(self.source.sensors)
        hello = Hello(self.subject, self.source.names, self.channels, self.source.rate, "binary", self.subject_info)
        self.ready = await self.server.open_local_subject(self.peer, hello)
        self.server.inputs.append(self)
        early, self._early = self._early, []
        self.counts["early"] = len(early)
        for f in early:
            self._malformed(f) if isinstance(f, Exception) else self._frame(f)
        pose_subject = getattr(self.source, "pose_subject", None)
        if pose_subject is not None:  # MVN: its own pose as another subject (MvnInput.pose_subject)
            await self.add_mvn_pose_subject(pose_subject)
        log.info("input %s: subject %d, %d sensors at %g Hz (%s)", self.source.name, self.subject,
                 len(self.source.sensors), self.source.rate, ", ".join(self.source.names))
        return self.ready

    async def add_mvn_pose_subject(self, subject: int) -> dict[str, Any]:
        """MVN only: publish MVN's own pose (type-02 datagrams) as subject ``subject`` beside the
        estimate (viewer, outputs), e.g. as ground truth for a sparse estimate."""
        sensors = tuple(segment_info(s, self.source.rate) for s in SEGMENTS)
        channels = canonical_channels(sensors)
        peer = _LocalPeer("mvn-pose")
        hello = Hello(subject, tuple(s.name for s in sensors), channels, self.source.rate, "binary", {})
        ready = await self.server.open_local_subject(peer, hello, factory=MvnPoseEstimator)

        def on_pose(seq: int, t: float, pos: Any, R: Any) -> None:
            try:
                data = canonical_frame(sensors, pose_frame(seq, t, pos, R), channels)
            except PacketError as exc:
                self.server.local_malformed(peer, subject, exc)
                return
            self.server.feed_local(peer, FramePacket(subject, seq, t, pose_frame(seq, t, pos, R).valid, data))

        self.source.on_pose = on_pose  # type: ignore[attr-defined]
        self._pose_subject = subject
        return ready

    async def stop(self) -> dict[str, Any]:
        """Close the input (its buffered frames are handed on) and end the subject."""
        await self.source.close()
        if getattr(self, "_pose_subject", None) is not None:
            await self.server.end_local_subject(self._pose_subject)
        if self.ready is None:
            return {}
        return await self.server.end_local_subject(self.subject)

    def _frame(self, f: DeviceFrame) -> None:
        if self.ready is None:
            self._early.append(f)
            return
        try:
            data = canonical_frame(self.source.sensors, f, self.channels)
        except PacketError as exc:
            self.counts["converted_malformed"] += 1
            self._malformed(exc)
            return
        self.counts["frames"] += 1
        self.server.feed_local(self.peer, FramePacket(self.subject, f.seq, f.timestamp, f.valid.copy(), data))

    def _malformed(self, exc: Exception) -> None:
        if self.ready is None:  # counted on the subject once it is open
            self._early.append(exc)
            return
        self.server.local_malformed(self.peer, self.subject, exc)

    def stats(self) -> dict[str, Any]:
        return {**self.source.stats(), "subject": self.subject, **self.counts}
