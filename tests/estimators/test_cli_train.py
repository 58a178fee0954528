"""``wearpose train``: help, argument errors, and a tiny run on the prepared corpus (if present)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch
from typer.testing import CliRunner

from wearpose.cli import app

runner = CliRunner()


def test_train_help_has_an_example() -> None:
    res = runner.invoke(app, ["train", "--help"])
    assert res.exit_code == 0 and "empose" in res.output, res.output
    res = runner.invoke(app, ["train", "empose", "--help"])
    assert res.exit_code == 0, res.output
    assert "Example: wearpose train empose" in res.output


def test_train_rejects_unknown_method(tmp_path: Path) -> None:
    res = runner.invoke(app, ["train", "no-such-method", "--out", str(tmp_path / "r")])
    assert res.exit_code != 0 and "no-such-method" in res.output


@pytest.mark.corpus
def test_tiny_cli_run_on_the_corpus(tmp_path: Path, corpus_store: Path) -> None:
    n = torch.get_num_threads()
    try:
        res = runner.invoke(app, ["train", "empose", "--config", "tiny", "--limit", "3", "--epochs", "1", "--threads", "1",
                                  "--out", str(tmp_path / "run"), "--json"])
    finally:
        torch.set_num_threads(n)
    assert res.exit_code == 0, res.output
    out = json.loads(res.output[res.output.index("{"):])
    assert out["method"] == "empose" and out["steps"] >= 1 and (tmp_path / "run" / "best.pt").is_file()


def test_train_rejects_unknown_or_misplaced_ablation(tmp_path: Path) -> None:
    res = runner.invoke(app, ["train", "empose", "--ablation", "no_legs", "--out", str(tmp_path / "r")])
    assert res.exit_code != 0 and "no_legs" in res.output and "no_t" in res.output, res.output
    res = runner.invoke(app, ["train", "empose", "--model", "birnn", "--ablation", "no_t", "--out", str(tmp_path / "r")])
    assert res.exit_code != 0 and "LGD-RNN" in res.output, res.output


@pytest.mark.corpus
def test_tiny_ablation_run_trains_the_ablated_config(tmp_path: Path, corpus_store: Path) -> None:
    n = torch.get_num_threads()
    try:
        res = runner.invoke(app, ["train", "empose", "--config", "tiny", "--ablation", "pos_only", "--limit", "2",
                                  "--epochs", "1", "--threads", "1", "--out", str(tmp_path / "run"), "--json"])
    finally:
        torch.set_num_threads(n)
    assert res.exit_code == 0, res.output
    out = json.loads(res.output[res.output.index("{"):])
    assert out["config"]["inputs"] == "position" and out["config"]["offsets"] == "random", out["config"]
