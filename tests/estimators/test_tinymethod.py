"""docs/contributing.md, "Adding a method": the tiny test method (``tests/estimators/tinymethod``,
one subpackage and one declaration) registered and run end to end through the commands the real
methods use: ``wearpose train tiny`` on clips of the corpus fixture, ``wearpose evaluate``,
``wearpose estimate REC --model <checkpoint>``, and ``wearpose serve`` in its own process (which
finds the method through a ``wearpose.methods`` entry point) streaming a recording over 127.0.0.1."""

from __future__ import annotations

import asyncio
import json
import math
import os
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any, Iterator

import pytest
import torch
from typer.testing import CliRunner

from tests.estimators.tinymethod import METHOD
from wearpose.cli import app
from wearpose.estimators import registry

REPO = Path(__file__).resolve().parents[2]
runner = CliRunner()


def _json(output: str) -> dict[str, Any]:
    return json.loads(output[output.index("{"):])


def _invoke(args: list[str]) -> dict[str, Any]:
    n = torch.get_num_threads()
    try:
        res = runner.invoke(app, args)
    finally:
        torch.set_num_threads(n)
    assert res.exit_code == 0, (args, res.output, res.exception)
    return _json(res.output)


def _register() -> bool:
    """Register the tiny method unless it is; True when this call did (and should unregister)."""
    if "tiny" in registry.list_methods():
        return False
    registry.register_method(METHOD)
    return True


@pytest.fixture
def tiny_method() -> Iterator[None]:
    mine = _register()
    yield
    if mine:
        registry.unregister_method("tiny")


def test_one_declaration_makes_the_train_command_the_estimator_and_the_protocol(tiny_method: None) -> None:
    res = runner.invoke(app, ["train", "--help"], env={"COLUMNS": "100"})
    assert res.exit_code == 0 and "tiny" in res.output and "Train the tiny test method" in res.output, res.output
    res = runner.invoke(app, ["train", "tiny", "--help"], env={"COLUMNS": "100"})
    assert res.exit_code == 0, res.output
    for option in ("--hidden", "--config", "--epochs", "--out", "--resume", "--threads", "--device", "--limit",
                   "--checkpoint-every", "--json"):  # its own option and every shared one
        assert option in res.output, (option, res.output)
    assert "Example: wearpose train tiny" in res.output and "Preset: tiny (the only one)." in res.output
    res = runner.invoke(app, ["train", "tiny", "--hidden", "0"])  # the declared bound, checked by the CLI
    assert res.exit_code != 0 and "--hidden" in res.output, res.output
    from tests.estimators.tinymethod.estimator import TinyEstimator
    from wearpose.evaluate.protocols import protocols

    assert registry.get_estimator("tiny") is TinyEstimator and "tiny" in registry.list_estimators()
    assert protocols()["tiny"] == "tests.estimators.tinymethod.entry:protocol"
    registry.unregister_method("tiny")
    res = runner.invoke(app, ["train", "tiny", "--help"])
    assert res.exit_code != 0 and "No such command 'tiny'" in res.output, res.output  # gone with its declaration
    registry.register_method(METHOD)


def test_a_clashing_declaration_is_refused(tiny_method: None) -> None:
    from dataclasses import replace

    from wearpose.errors import ConfigError

    with pytest.raises(ConfigError, match="estimator names \\['pip'\\] belong to another method"):
        registry.register_method(replace(METHOD, name="tiny2", estimators=(replace(METHOD.estimators[0], name="pip"),)))
    with pytest.raises(ConfigError, match="method 'tiny' is declared already"):
        registry.register_method(replace(METHOD, summary="another tiny"))


@pytest.fixture(scope="module")
def tiny_run(corpus_root: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Any]]:
    """``wearpose train tiny`` on two clips of the corpus fixture, and one simulated test recording."""
    mine = _register()
    out = tmp_path_factory.mktemp("tiny")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("WEARPOSE_CACHE", str(corpus_root))
        train = _invoke(["train", "tiny", "--limit", "2", "--epochs", "2", "--threads", "1", "--out",
                         str(out / "run"), "--json"])
        sim = _invoke(["simulate", "--kit", "imu6", "--split", "test", "--limit", "1", "--out", str(out / "sim"),
                       "--json"])
    rec = next((out / "sim").rglob("*.npz"))
    yield {"train": train, "out": out, "checkpoint": out / "run" / "best.pt", "recording": rec, "simulate": sim}
    if mine:
        registry.unregister_method("tiny")


@pytest.mark.corpus
def test_train_tiny_trains_on_the_corpus_clips(tiny_run: dict[str, Any]) -> None:
    from wearpose.estimators.checkpoint import load_checkpoint

    r = tiny_run["train"]
    assert r["method"] == "tiny" and r["steps"] >= 2 and len(r["history"]) == 2, r
    assert math.isfinite(r["best"]) and r["best"] == min(h["val_mpjae_deg"] for h in r["history"])
    ck = load_checkpoint(tiny_run["checkpoint"])
    assert ck.method == "tiny" and ck.kit == "imu6" and ck.meta["train_clips"] == 2, ck.meta


@pytest.mark.corpus
@pytest.mark.budget(30)  # two commands in-process (evaluate: 2 clips simulated and estimated)
def test_evaluate_and_estimate_run_the_tiny_checkpoint(tiny_run: dict[str, Any], corpus_store: Path,
                                                       tmp_path: Path) -> None:
    ev = _invoke(["evaluate", str(tiny_run["checkpoint"]), "--clips", "2", "--json"])
    (m,) = ev["models"].values()
    assert m["method"] == "tiny" and m["clips"] == 2 and m["frames"] > 0 and m["kit"] == "imu6", m
    assert 0 < m["metrics"]["mpjae_deg"] < 180, m["metrics"]
    est = _invoke(["estimate", str(tiny_run["recording"]), "--model", str(tiny_run["checkpoint"]), "--out",
                   str(tmp_path / "pose.npz"), "--json"])
    assert (tmp_path / "pose.npz").is_file(), est
    from wearpose.motion import read_amass
    from wearpose.recording import load_recording

    frames = load_recording(tiny_run["recording"]).sensor("pelvis").num_frames
    assert read_amass(tmp_path / "pose.npz").num_frames == frames


def _entry_point_site(root: Path) -> Path:
    """A folder holding the distribution metadata of a package that declares the tiny method as a
    ``wearpose.methods`` entry point (what ``pip install`` of a plug-in would leave)."""
    dist = root / "site" / "wearpose_tinymethod-0.1.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: wearpose-tinymethod\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text(f"[{registry.ENTRY_POINT_GROUP}]\ntiny = tests.estimators.tinymethod:METHOD\n")
    return root / "site"


@pytest.mark.corpus
@pytest.mark.budget(40)  # a wearpose serve process (imports torch) started and stopped: 16-19 s elsewhere
def test_serve_streams_the_tiny_checkpoint(tiny_run: dict[str, Any], tmp_path: Path) -> None:
    from wearpose.recording import load_recording
    from wearpose.stream import replay

    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(_entry_point_site(tmp_path)), str(REPO)])}
    server = subprocess.Popen([sys.executable, "-m", "wearpose.cli", "serve", "--model", str(tiny_run["checkpoint"]),
                               "--port", "0", "--max-lag", "0", "--log-level", "ERROR", "--json"],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        line = server.stdout.readline()
        assert " on ws://127.0.0.1:" in line, (line, server.stderr.read() if server.poll() is not None else "")
        rec = load_recording(tiny_run["recording"])
        r = asyncio.run(replay(rec, line.strip().split(" on ")[-1], realtime=False))
    finally:
        server.send_signal(signal.SIGINT)
        rest, err = server.communicate(timeout=60)
    assert server.returncode == 0, err
    frames = rec.sensor("pelvis").num_frames
    assert r["frames_sent"] == frames and r["poses_received"] == frames and r["frames_lost"] == 0, r
    final = json.loads(rest)
    assert final["finished"]["0"]["estimated"] == frames, final
