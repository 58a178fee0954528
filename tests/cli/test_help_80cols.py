"""Help and doctor text at 80 columns keep what they say: an extra's name in brackets is not
eaten as rich markup, and doctor names the extra to install."""

from __future__ import annotations

import re

from typer.testing import CliRunner

from wearpose.cli.app import app


def test_simulate_help_names_the_ray_extra_at_80_columns() -> None:
    res = CliRunner().invoke(app, ["simulate", "--help"], env={"COLUMNS": "80", "TERM": "dumb"})
    assert res.exit_code == 0, res.output
    assert "'wearpose[ray]'" in res.output  # rich took "[ray]" for a style tag and dropped it


def test_doctor_hint_names_the_extra_of_each_optional_dependency() -> None:
    from wearpose.diagnostics import _pins, check_dependencies

    extras = {d: x for d, (_, x) in _pins().items() if x}
    assert extras, "pyproject declares optional extras (ray, asset, bench...)"
    for c in check_dependencies():
        if c.status == "warn":
            assert "[...]" not in c.hint
            m = re.search(r'pip install "wearpose\[([a-z0-9_-]+)\]"', c.hint)
            assert m and m.group(1) == extras[c.name], c.hint
