"""Every command's help reflows at 80 columns: no sentence broken where the docstring was wrapped."""

from __future__ import annotations

import re

import pytest
import typer
from typer.testing import CliRunner

from wearpose.cli import app
from wearpose.cli.helptext import _OWN_LINE, reflow


def _command_paths(t: typer.Typer, prefix: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    paths = [prefix + (c.name or c.callback.__name__.replace("_", "-"),) for c in t.registered_commands]
    for g in t.registered_groups:
        paths += [prefix + (g.name,)] + _command_paths(g.typer_instance, prefix + (g.name,))
    return paths


def test_reflow_joins_wrapped_lines_and_keeps_examples_and_lists() -> None:
    doc = ("Title line.\n\nA sentence wrapped\nat a narrow width. And more.\n\n"
           "Example: wearpose info\nOther: wearpose info --json\n- item one\n- item two\n\fhidden\nkept")
    assert reflow(doc) == ("Title line.\n\nA sentence wrapped at a narrow width. And more.\n\n"
                           "Example: wearpose info\nOther: wearpose info --json\n- item one\n- item two\n"
                           "\fhidden\nkept")


def _broken_lines(text: str, width: int = 80) -> list[str]:
    """Description lines after which rich would have put the next word had the docstring not broken there."""
    desc = text.split("╭", 1)[0].splitlines()
    bad = []
    for line, nxt in zip(desc, desc[1:]):
        a, b = line.strip(), nxt.strip()
        if not a or not b or _OWN_LINE.match(b):
            continue
        if len(a) + 1 + len(b.split()[0]) <= width - 4:  # rich keeps one column of margin each side
            bad.append(f"{a!r} / {b!r}")
    return bad


@pytest.mark.parametrize("path", _command_paths(app), ids=" ".join)
def test_help_has_no_broken_sentences_at_80_columns(path: tuple[str, ...]) -> None:
    res = CliRunner().invoke(app, [*path, "--help"], env={"COLUMNS": "80", "TERM": "dumb"})
    assert res.exit_code == 0, res.output
    assert _broken_lines(res.output) == [], f"wearpose {' '.join(path)} --help"


def test_the_check_sees_a_broken_sentence() -> None:
    # The docstring layout this module fixes, as typer prints it without the reflow.
    text = " Evaluate on held-out recordings.\n\n EM-POSE models: every clip is simulated once (kit noise, a\n synthetic subject's\n sensor offsets).\n╭─ Options"
    assert re.search("synthetic subject's", _broken_lines(text)[0])
