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


def _train(args: list[str]) -> dict:
    """``wearpose train ARGS --json`` in-process (torch's thread count restored), its JSON result."""
    n = torch.get_num_threads()
    try:
        res = runner.invoke(app, ["train", *args, "--json"])
    finally:
        torch.set_num_threads(n)
    assert res.exit_code == 0, res.output
    return json.loads(res.output[res.output.index("{"):])


@pytest.mark.corpus
def test_tiny_cli_run_on_the_corpus(tmp_path: Path, corpus_store: Path) -> None:
    out = _train(["empose", "--config", "tiny", "--limit", "3", "--epochs", "1", "--threads", "1",
                  "--out", str(tmp_path / "run")])
    assert out["method"] == "empose" and out["steps"] >= 1 and (tmp_path / "run" / "best.pt").is_file()
    # the config kept with the weights (and shown on their card) says the run's length, not the preset's
    from wearpose.estimators.checkpoint import load_checkpoint

    assert out["config"]["epochs"] == 1 == load_checkpoint(tmp_path / "run" / "best.pt").config["epochs"]


def test_train_rejects_unknown_or_misplaced_ablation(tmp_path: Path) -> None:
    res = runner.invoke(app, ["train", "empose", "--ablation", "no_legs", "--out", str(tmp_path / "r")])
    assert res.exit_code != 0 and "no_legs" in res.output and "no_t" in res.output, res.output
    res = runner.invoke(app, ["train", "empose", "--model", "birnn", "--ablation", "no_t", "--out", str(tmp_path / "r")])
    assert res.exit_code != 0 and "LGD-RNN" in res.output, res.output


@pytest.mark.corpus
def test_tiny_ablation_run_trains_the_ablated_config(tmp_path: Path, corpus_store: Path) -> None:
    out = _train(["empose", "--config", "tiny", "--ablation", "pos_only", "--limit", "2", "--epochs", "1",
                  "--threads", "1", "--out", str(tmp_path / "run")])
    assert out["config"]["inputs"] == "position" and out["config"]["offsets"] == "random", out["config"]


def test_source_restricts_the_training_store(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Issue 24, unseen lab: ``--source`` trains (and validates) on one source's clips."""
    from wearpose.estimators.method import OptionError, TrainRun
    from wearpose.motion.store import write_index

    clips = {f"{s}/x/{sp}{i}": {"id": f"{s}/x/{sp}{i}", "clip": f"{sp}{i}", "subject": "x", "source": s, "split": sp,
                                "licence": "l", "description": "walk", "file": "x.npz"}
             for s in ("bandai", "cmu_daz") for sp in ("train", "val") for i in range(2)}
    write_index(tmp_path, clips, {}, corpus={"kind": "test"}, converter="t", fps=None, rest_joints=[], rest_source="t")
    monkeypatch.setenv("WEARPOSE_CACHE", str(tmp_path))
    assert TrainRun().corpus_store() is None and TrainRun().loop()["store"] is None
    store = TrainRun(source="cmu_daz").loop()["store"]
    assert store.clips(split="train") == ["cmu_daz/x/train0", "cmu_daz/x/train1"] and store.sources_only == ("cmu_daz",)
    with pytest.raises(OptionError, match="no clips of source 'cmu_asf'") as err:
        TrainRun(source="cmu_asf").corpus_store()
    assert err.value.option == "--source"
    res = runner.invoke(app, ["train", "empose", "--config", "tiny", "--source", "cmu_asf", "--out", str(tmp_path / "r")])
    assert res.exit_code == 2 and "--source" in res.output and "'cmu_asf'" in res.output, res.output


@pytest.mark.corpus
def test_tiny_run_on_one_source_records_it(tmp_path: Path, corpus_store: Path) -> None:
    from wearpose.estimators.checkpoint import load_checkpoint

    _train(["empose", "--config", "tiny", "--source", "cmu_daz", "--limit", "2", "--epochs", "1", "--threads", "1",
            "--out", str(tmp_path / "run")])
    meta = load_checkpoint(tmp_path / "run" / "best.pt").meta
    assert meta["train_sources"] == ["cmu_daz"] and meta["train_clips"] == 2, meta


@pytest.mark.parametrize("method, module, entry", [("empose", "wearpose.estimators.empose.train", "train_empose"),
                                                   ("pip", "wearpose.estimators.pip.train", "train_pip"),
                                                   ("miposer", "wearpose.estimators.miposer.train", "train_miposer")])
def test_epochs_reach_the_config_the_card_shows(method: str, module: str, entry: str, tmp_path: Path,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """``--epochs`` is the config's ``epochs`` (a card said the preset's 20 for a 5-epoch run);
    unset keeps the preset's."""
    import importlib

    seen: list[int] = []

    def fake_train(est: object, out: Path, **kw: object) -> dict:
        seen.append(est.config.epochs)  # type: ignore[attr-defined]
        return {"steps": 0}

    monkeypatch.setattr(importlib.import_module(module), entry, fake_train)
    preset = _train([method, "--config", "tiny", "--out", str(tmp_path / "r")])["config"]["epochs"]
    out = _train([method, "--config", "tiny", "--epochs", str(preset + 2), "--out", str(tmp_path / "r")])
    assert seen == [preset, preset + 2] and out["config"]["epochs"] == preset + 2


def test_lambda_shape_reaches_the_config(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``--lambda-shape`` (issue 24) sets EmposeConfig.lambda_shape of the run; unset keeps the preset's 1.0;
    a negative weight is refused by the option."""
    import wearpose.estimators.empose.train as empose_train

    seen: list[float] = []

    def fake_train(est: object, out: Path, **_: object) -> dict:
        seen.append(est.config.lambda_shape)  # type: ignore[attr-defined]
        return {"steps": 0}

    monkeypatch.setattr(empose_train, "train_empose", fake_train)
    for extra, want in (([], 1.0), (["--lambda-shape", "0.05"], 0.05)):
        out = _train(["empose", "--config", "tiny", "--out", str(tmp_path / "r"), *extra])
        assert seen[-1] == want and out["config"]["lambda_shape"] == want, (extra, seen, out["config"]["lambda_shape"])
    res = runner.invoke(app, ["train", "empose", "--lambda-shape", "-1", "--out", str(tmp_path / "r")])
    assert res.exit_code == 2 and "--lambda-shape" in res.output, res.output
