"""``wearpose train miposer``: help, argument errors, a tiny run on the prepared corpus (marked corpus)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from wearpose.cli import app

runner = CliRunner()


def test_help_has_an_example() -> None:
    res = runner.invoke(app, ["train", "miposer", "--help"])
    assert res.exit_code == 0, res.output
    assert "Example: wearpose train miposer" in res.output


@pytest.mark.parametrize("args,hint", [(["--model", "lstm"], "lstm"), (["--wrists", "3"], "wrists")])
def test_bad_arguments(tmp_path: Path, args, hint) -> None:
    res = runner.invoke(app, ["train", "miposer", *args, "--out", str(tmp_path / "r")])
    assert res.exit_code != 0 and hint in res.output


@pytest.mark.corpus
def test_tiny_run_on_the_corpus(tmp_path: Path, corpus_store: Path) -> None:
    res = runner.invoke(app, ["train", "miposer", "--config", "tiny", "--limit", "2", "--epochs", "1", "--threads", "1",
                              "--out", str(tmp_path / "run"), "--json"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.output[res.output.index("{"):])
    assert out["method"] == "miposer" and (tmp_path / "run" / "last.pt").is_file()
