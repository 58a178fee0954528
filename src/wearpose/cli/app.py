"""Typer application. Subcommands print human output by default and JSON with ``--json``."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any, Optional

import typer
from rich.console import Console
from rich.table import Table

from wearpose.errors import WearposeError

app = typer.Typer(
    name="wearpose",
    help="Full-body, SMPL-compatible motion from a few body-worn sensors.\n\n"
    "Example: wearpose info --json",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
data_app = typer.Typer(help="Prepare and inspect the motion corpus.\n\nExample: wearpose data prepare && wearpose data info",
                       no_args_is_help=True)
app.add_typer(data_app, name="data")
console = Console(stderr=False)
err_console = Console(stderr=True)


def _emit(obj: dict[str, Any], as_json: bool, render: Any) -> None:
    if as_json:
        sys.stdout.write(json.dumps(obj, indent=2, default=str) + "\n")
    else:
        render(obj)


def _kv_table(title: str, rows: dict[str, Any]) -> Table:
    t = Table(title=title, show_header=False)
    for k, v in rows.items():
        t.add_row(str(k), str(v))
    return t


def body_info(source: Optional[str] = None) -> dict[str, Any]:
    """Facts about a body asset (what ``wearpose info`` prints)."""
    from wearpose.body import BodyModel

    body = BodyModel(source)
    out = body()
    verts = out.vertices
    return {
        "asset_id": body.asset_id,
        "source": body.meta.get("source", ""),
        "licence": body.meta.get("licence", ""),
        "vertices": body.num_vertices,
        "faces": int(body.faces.shape[0]),
        "joints": 24,
        "shape_dims": body.num_betas,
        "pose_correctives": body.has_posedirs,
        "rest_height_m": round(float(verts[:, 1].max() - verts[:, 1].min()), 4),
        "sensor_sites": list(body.site_names),
    }


@app.command()
def info(
    body: Optional[str] = typer.Option(None, help="Body asset: default, smpl ($WEARPOSE_SMPL_MODEL) or a file path."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON for scripts."),
) -> None:
    """Report the body asset in use and the prepared corpus.

    Example: wearpose info --json
    """
    result: dict[str, Any] = {"body": body_info(body)}
    try:
        from wearpose.motion import CorpusStore, default_cache_dir

        store = CorpusStore(default_cache_dir())
        result["corpus"] = store.summary()
    except (ImportError, WearposeError, FileNotFoundError) as exc:
        result["corpus"] = {"prepared": False, "reason": str(exc)}

    def render(r: dict[str, Any]) -> None:
        console.print(_kv_table("body asset", r["body"]))
        console.print(_kv_table("corpus", {k: v for k, v in r["corpus"].items()}))

    _emit(result, as_json, render)


def main() -> None:
    """Console entry point: turns library errors into one clear line and exit code 1."""
    try:
        app()
    except WearposeError as exc:
        err_console.print(f"[bold red]error:[/] {exc}")
        raise SystemExit(1) from None
