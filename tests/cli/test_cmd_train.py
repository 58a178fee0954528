"""``wearpose train <method>`` generated from the method declarations: every option name and
default of the former hand-written commands (pinned below, as they were before issue 21.4),
the help at 80 columns, a refused value reported as that option's error."""

from __future__ import annotations

from pathlib import Path
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


#: The library's former argparse ``main()``s (``python -m wearpose.estimators.empose.twostage``,
#: ``... .empose.optimization``, ``wearpose.interference.nbeats``), now ``wearpose train`` commands:
#: every former option with its default; added: ``--json`` to all, and to empose-twostage the shared
#: ``--device`` / ``--checkpoint-every`` at the defaults the old main passed on implicitly.
#: ``--out`` of empose-twostage was required there and still is (checked below).
FORMER_MAINS: dict[str, dict[str, Any]] = {
    "empose-twostage": {"--sensors": 12, "--config": "cpu", "--ik": "lgd", "--mapper-input": "raw", "--init": None,
                        "--epochs": None, "--lr": None, "--out": None, "--resume": False, "--threads": None,
                        "--limit": None, "--limit-val": None, "--max-steps": None, "--fk-weight": None,
                        "--device": "auto", "--checkpoint-every": 100, "--json": False},
    "poseprior": {"--out": Path("runs/poseprior_cpu"), "--epochs": 4, "--threads": 1, "--limit": None, "--json": False},
    "nbeats": {"--ship": None, "--name": "nbeats_cpu", "--config": "cpu", "--out": Path("runs/nbeats_cpu"),
               "--resume": False, "--threads": 1, "--epochs": None, "--max-train-clips": None, "--json": False},
}
BEFORE.update(FORMER_MAINS)


def _options(method: str) -> dict[str, Any]:
    group = typer.main.get_command(app).get_command(None, "train")  # type: ignore[union-attr, arg-type]
    cmd = group.get_command(None, method)
    return {"/".join([*p.opts, *p.secondary_opts]): p.default for p in cmd.params if p.name != "help"}


#: Options every method's command gained since (issue 24: --source, the unseen-lab protocol's training side).
ADDED: dict[str, Any] = {"--source": None}
#: Options the four methods gained with the shared training mix (issue 24.3, MIX_OPTIONS): the seed,
#: --init-from for every one, and the mix (--families: which procedural families; --rest-offset: the
#: capture-chain offsets). PIP's --speed-copies was 0 and is None now: "the preset's",
#: which is 0 in every preset (the same run).
MIX_ADDED: dict[str, Any] = {"--seed": None, "--init-from": None, "--mirror": False, "--speed-copies": None,
                             "--heading-copies": None, "--mix-copies": None, "--site-jitter": None,
                             "--rest-offset": None, "--rest-offset-joints": None,
                             "--procedural": None, "--shapes": None, "--families": None}
#: Own options the methods gained since: --lr for EM-POSE and MI-Poser (fine-tuning recipes);
#: EM-POSE's --lambda-shape (issue 24: with wearers of every size the shape loss outweighs the pose loss).
OWN_ADDED: dict[str, dict[str, Any]] = {"empose": {"--lr": None, "--lambda-shape": None}, "miposer": {"--lr": None},
                                        "nbeats": {"--notes": None}, "birae": {"--epochs-sigma": None}}
#: The N-BEATS forecaster took the training mix with its recipe (issue 24.5), all of it but what
#: has no meaning for wrist trajectories: --site-jitter (no simulated sensors) and --init-from.
NBEATS_MIX = {k: v for k, v in MIX_ADDED.items() if k not in ("--site-jitter", "--init-from")}
#: The two-stage EM-POSE took the training mix and the seed too (its recipe, issue 24.5); its own
#: --init warm-starts it, so it has no --init-from.
TWOSTAGE_MIX = {k: v for k, v in MIX_ADDED.items() if k != "--init-from"}


@pytest.mark.parametrize("method", sorted(BEFORE))
def test_every_former_option_keeps_its_name_and_default(method: str) -> None:
    mix = (MIX_ADDED if method in ("empose", "pip", "birae", "miposer") else
           {"nbeats": NBEATS_MIX, "empose-twostage": TWOSTAGE_MIX}.get(method, {}))
    assert _options(method) == {**BEFORE[method], **ADDED, **mix, **OWN_ADDED.get(method, {})}


@pytest.mark.parametrize("method", sorted(BEFORE))
def test_help_at_80_columns_has_its_example_and_no_broken_sentence(method: str) -> None:
    res = CliRunner().invoke(app, ["train", method, "--help"], env={"COLUMNS": "80", "TERM": "dumb"})
    assert res.exit_code == 0, res.output
    assert f"Example: wearpose train {method}" in res.output.replace("\n", " ")
    assert _broken_lines(res.output) == [], res.output


def test_a_refused_value_is_that_options_error(tmp_path) -> None:  # noqa: ANN001
    res = CliRunner().invoke(app, ["train", "birae", "--rep", "9param", "--out", str(tmp_path / "r")])
    assert res.exit_code == 2 and "Invalid value for --rep" in res.output and "9param" in res.output, res.output


def _train(args: list[str]) -> dict[str, Any]:
    """``wearpose train ARGS --json`` (sys.argv as the command line would set it: the recorded
    ``train_command`` is made from it)."""
    import json
    import sys

    import torch

    n, argv = torch.get_num_threads(), sys.argv
    sys.argv = ["wearpose", "train", *args, "--json"]
    try:
        res = CliRunner().invoke(app, sys.argv[1:])
    finally:
        torch.set_num_threads(n)
        sys.argv = argv
    assert res.exit_code == 0, (args, res.output, res.exception)
    return json.loads(res.output[res.output.index("{"):])


def test_empose_twostage_requires_out_and_warm_starts_from_its_own_run(corpus_store: Path, tmp_path: Path) -> None:
    res = CliRunner().invoke(app, ["train", "empose-twostage", "--config", "tiny"])
    assert res.exit_code == 2 and "Invalid value for --out" in res.output, res.output
    first = _train(["empose-twostage", "--config", "tiny", "--limit", "2", "--limit-val", "1", "--max-steps", "2",
                    "--threads", "1", "--out", str(tmp_path / "a")])
    assert first["method"] == "empose-twostage" and first["config"]["ik"] == "lgd" and first["steps"] == 2, first
    warm = _train(["empose-twostage", "--config", "tiny", "--ik", "closed", "--mapper-input", "site", "--init",
                   str(tmp_path / "a" / "last.pt"), "--limit", "2", "--limit-val", "1", "--max-steps", "1",
                   "--fk-weight", "50", "--mirror", "--procedural", "1", "--families", "squat", "--seed", "3",
                   "--threads", "1", "--out", str(tmp_path / "b")])
    assert warm["config"]["ik"] == "closed" and warm["config"]["mapper_input"] == "site", warm
    # the training mix and the seed reach the two-stage config as they reach EM-POSE's
    assert warm["config"]["aug_mirror"] and warm["config"]["procedural_per_family"] == 1, warm
    assert warm["config"]["procedural_families"] == ["squat"] and warm["config"]["seed"] == 3, warm
    from wearpose.estimators.checkpoint import load_checkpoint
    from wearpose.estimators.empose import twostage

    meta = load_checkpoint(tmp_path / "b" / "last.pt").meta
    assert meta["warm_start"]["optimizer"] is True and meta["fk_joint_weight"] == 50.0, meta
    assert twostage.FK_JOINT_WEIGHT == 100.0  # the override lasted the run only
    assert load_checkpoint(tmp_path / "b" / "last.pt").train_command.startswith("wearpose train empose-twostage --config")


def test_poseprior_writes_the_lbfgs_prior(corpus_store: Path, tmp_path: Path) -> None:
    r = _train(["poseprior", "--limit", "2", "--epochs", "1", "--out", str(tmp_path / "p")])
    assert r["method"] == "empose-lbfgs" and len(r["history"]) == 1 and r["best_val_rec"] > 0, r
    from wearpose.estimators.checkpoint import load_checkpoint

    ck = load_checkpoint(tmp_path / "p" / "prior.pt")
    assert ck.method == "empose-lbfgs" and ck.train_command.startswith("wearpose train poseprior"), ck.train_command


def test_nbeats_trains_then_ships_with_its_test_figures(corpus_store: Path, tmp_path: Path,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    import wearpose.weights

    r = _train(["nbeats", "--config", "tiny", "--max-train-clips", "2", "--epochs", "1", "--out", str(tmp_path / "n")])
    assert r["method"] == "nbeats" and r["epochs"] == 1 and r["best_val_mae_cm"] > 0, r
    monkeypatch.setattr(wearpose.weights, "WEIGHTS_DIR", tmp_path / "w")
    (tmp_path / "w").mkdir()
    s = _train(["nbeats", "--ship", str(tmp_path / "n" / "best.pt"), "--name", "nb_test", "--notes", "Version 0."])
    assert s["shipped"] == str(tmp_path / "w" / "nb_test.pt") and s["test"]["mae_cm"] > 0, s
    import json

    card = json.loads((tmp_path / "w" / "nb_test.json").read_text())
    assert card["train_command"].startswith("wearpose train nbeats") and card["test"]["mae_cm"] == s["test"]["mae_cm"]
    assert card["notes"].startswith("Version 0. MI-Poser reports")
