"""``wearpose doctor``: check the environment and say what is missing (calls :mod:`wearpose.diagnostics`)."""

from __future__ import annotations

from typing import Any

import typer
from rich.markup import escape
from rich.table import Table

from wearpose.cli.app import _emit, app, console

_STYLE = {"ok": "green", "warn": "yellow", "fail": "bold red"}


@app.command()
def doctor(
    as_json: bool = typer.Option(False, "--json", help="Print the report as JSON."),
) -> None:
    """Check Python, pinned dependencies, torch/CUDA, the body asset and SMPL file, the motion corpus
    and prepared store, shipped weights, estimators and optional tools; say what is missing.

    Exit code 1 when a required part fails (warnings are optional features).

    Example: wearpose doctor --json
    """
    from wearpose.diagnostics import run_checks, summary  # start-up: wearpose.diagnostics adds ~21 ms to wearpose --help

    res = summary(run_checks())

    def render(r: dict[str, Any]) -> None:
        t = Table(title="wearpose doctor")
        for col in ("area", "check", "status", "found", "what to do"):
            t.add_column(col, overflow="fold")
        for c in r["checks"]:
            t.add_row(c["area"], c["name"], f"[{_STYLE[c['status']]}]{c['status']}[/]", escape(c["detail"]),
                      escape(c["hint"]))  # details quote errors whose [field] rich would take for markup
        console.print(t)
        n = r["counts"]
        console.print(f"{n['ok']} ok, {n['warn']} warnings (optional), {n['fail']} failures")

    _emit(res, as_json, render)
    if not res["ok"]:
        raise typer.Exit(code=1)
