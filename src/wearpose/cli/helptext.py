"""Command help that reflows at any terminal width.

Typer keeps every single line break of a docstring's later paragraphs, so a docstring wrapped at
100 columns prints at 80 as a long line, a stub of two words, a long line, ... This module joins
the lines of each paragraph into one (rich then wraps it at the terminal's width) and keeps a line
break only where it means something: before an example line (``Example: wearpose ...`` or
``Unseen wearers: wearpose ...``), a list item (``- ``, ``* ``) or a table row (``| ``).
"""

from __future__ import annotations

import inspect
import re

import typer

#: A line that starts a new line of its own: an example command, a list item or a table row.
_OWN_LINE = re.compile(r"^(Example\b|[^:]{0,80}: (wearpose|python|torchrun)\b|[-*] |\| )")


def reflow(text: str) -> str:
    """``text`` with each paragraph's wrapped lines joined; paragraphs (blank-line separated),
    example lines, list items and table rows kept, and everything after a ``\\f`` line left as is."""
    head, sep, tail = inspect.cleandoc(text).partition("\f")
    body = head.rstrip("\n")
    paragraphs = []
    for para in body.split("\n\n"):
        if para.startswith("\b"):  # click's "do not rewrap" marker
            paragraphs.append(para)
            continue
        lines: list[str] = []
        for line in para.split("\n"):
            if lines and not _OWN_LINE.match(line.strip()):
                lines[-1] = f"{lines[-1].rstrip()} {line.strip()}"
            else:
                lines.append(line.strip())
        paragraphs.append("\n".join(lines))
    return "\n\n".join(paragraphs) + head[len(body):] + sep + tail


def reflow_app(app: typer.Typer) -> None:
    """Reflow the help of every command and group of ``app``, recursively (in place)."""
    if app.info.help and isinstance(app.info.help, str):
        app.info.help = reflow(app.info.help)
    for cmd in app.registered_commands:
        doc = cmd.help if cmd.help is not None else inspect.getdoc(cmd.callback)
        if doc:
            cmd.help = reflow(doc)
    for group in app.registered_groups:
        if group.help:
            group.help = reflow(group.help)
        reflow_app(group.typer_instance)
