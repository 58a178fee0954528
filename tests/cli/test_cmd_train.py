"""``wearpose train <method>`` generated from the method declarations: every option name and
default of the former hand-written commands (pinned below, as they were before issue 21.4),
the help at 80 columns, a refused value reported as that option's error."""

from __future__ import annotations

from typing import Any

import pytest
import typer
from typer.testing import CliRunner

from tests.cli.test_helptext import _broken_lines
from wearpose.cli import app

#: method -> {option: default} of the hand-written commands (cli/cmd_train*.py before the declarations).
BEFORE: dict[str, dict[str, Any]] = {
    "empose": {"--sensors": 12, "--config": "cpu", "--model": "lgd", "--epochs": None, "--out": None, "--resume": False,
               "--threads": None, "--device": "auto", "--hidden": None, "--width": None, "--iterations": None,
               "--batch-size": None, "--offsets": None, "--ablation": None, "--limit": None, "--checkpoint-every": 100,
               "--json": False},
    "pip": {"--config": "cpu", "--epochs": None, "--out": None, "--resume": False, "--threads": None, "--device": "auto",
            "--hidden": None, "--batch-size": None, "--learned-init/--no-learned-init": True, "--limit": None,
            "--sitting-clips": None, "--balanced-sitting": False, "--sitting-transitions": None,
            "--sitting-hanging-arms": None, "--mirror": False, "--speed-copies": 0, "--seq-len": None,
            "--window-stride": None, "--min-window": None, "--sitting-window": None, "--lr": None, "--init-from": None,
            "--checkpoint-every": 100, "--json": False},
    "birae": {"--rep": "6param", "--config": "cpu", "--epochs-clean": None, "--epochs-aug": None, "--out": None,
              "--resume": False, "--threads": None, "--device": "cpu", "--hidden": None, "--width": None,
              "--batch-size": None, "--train-clips": None, "--checkpoint-every": 50, "--init-from": None, "--lr": None,
              "--json": False},
    "miposer": {"--config": "cpu", "--model": "avatarposer", "--wrists": 2, "--epochs": None, "--out": None,
                "--resume": False, "--threads": None, "--device": "auto", "--batch-size": None, "--limit": None,
                "--checkpoint-every": 100, "--json": False},
}


def _options(method: str) -> dict[str, Any]:
    group = typer.main.get_command(app).get_command(None, "train")  # type: ignore[union-attr, arg-type]
    cmd = group.get_command(None, method)
    return {"/".join([*p.opts, *p.secondary_opts]): p.default for p in cmd.params if p.name != "help"}


@pytest.mark.parametrize("method", sorted(BEFORE))
def test_every_former_option_keeps_its_name_and_default(method: str) -> None:
    assert _options(method) == BEFORE[method]


@pytest.mark.parametrize("method", sorted(BEFORE))
def test_help_at_80_columns_has_its_example_and_no_broken_sentence(method: str) -> None:
    res = CliRunner().invoke(app, ["train", method, "--help"], env={"COLUMNS": "80", "TERM": "dumb"})
    assert res.exit_code == 0, res.output
    assert f"Example: wearpose train {method}" in res.output
    assert _broken_lines(res.output) == [], res.output


def test_a_refused_value_is_that_options_error(tmp_path) -> None:  # noqa: ANN001
    res = CliRunner().invoke(app, ["train", "birae", "--rep", "9param", "--out", str(tmp_path / "r")])
    assert res.exit_code == 2 and "Invalid value for --rep" in res.output and "9param" in res.output, res.output
