"""Real-time streaming: a WebSocket server running an estimator's online ``step`` per subject,
its packet formats (JSON and binary), a client and a recording replay tool.

Public API: :class:`StreamServer`, :func:`run_server`, :func:`estimator_factory`,
:class:`ReorderBuffer`, :class:`StreamClient`, :func:`replay`, :class:`Faults`, and the packet
types/codecs of :mod:`wearpose.stream.packets` (contract in ``docs/streaming.md``).
"""

from wearpose.stream import packets
from wearpose.stream.client import StreamClient, StreamError
from wearpose.stream.packets import *  # noqa: F403 - the packet API, listed once in packets.__all__
from wearpose.stream.replay import Faults, replay, stack_recording
from wearpose.stream.server import ReorderBuffer, StreamServer, estimator_factory, run_server

__all__ = [
    "StreamServer", "run_server", "estimator_factory", "ReorderBuffer", "StreamClient", "StreamError",
    "replay", "Faults", "stack_recording", *packets.__all__,
]
