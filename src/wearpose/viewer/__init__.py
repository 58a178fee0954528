"""Viewing motion on the body. Public entry: :func:`write_html` (self-contained offline page)."""

from wearpose.viewer.html import write_html

__all__ = ["write_html"]
