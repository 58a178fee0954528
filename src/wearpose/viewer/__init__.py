"""Viewing motion on the body.

Public entry: :func:`write_html` (self-contained offline page, no server), and the viser-based
browser viewers :class:`RecordingViewer` (offline: a recording / estimate with a timeline) and
:class:`LiveViewer` (subscribes to a streaming server), imported lazily (they pull in viser).
"""

from typing import Any

from wearpose.viewer.html import write_html

__all__ = ["write_html", "RecordingViewer", "LiveViewer", "run_live_viewer", "run_recording_viewer"]


def __getattr__(name: str) -> Any:
    if name in ("RecordingViewer", "LiveViewer", "run_live_viewer", "run_recording_viewer"):
        from wearpose.viewer import live

        return getattr(live, name)
    raise AttributeError(f"module 'wearpose.viewer' has no attribute {name!r}")
