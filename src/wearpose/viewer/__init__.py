"""Viewing motion on the body.

Public entry: :func:`write_html` (self-contained offline page, no server), and the viser-based
browser viewers :class:`RecordingViewer` (offline: a recording / estimate with a timeline) and
:class:`LiveViewer` (subscribes to a streaming server); viser itself loads when a viewer starts.
"""

from wearpose.viewer.html import write_html
from wearpose.viewer.live import LiveViewer, RecordingViewer, run_live_viewer, run_recording_viewer

__all__ = ["write_html", "RecordingViewer", "LiveViewer", "run_live_viewer", "run_recording_viewer"]
