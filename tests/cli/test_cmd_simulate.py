"""``wearpose simulate``: help, JSON output, a process pool giving the same files as one process."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from tests.recording.dataset_testutils import make_mini_store
from wearpose.cli import app
from wearpose.recording import load_recording
from wearpose.recording.dataset import simulate_corpus

runner = CliRunner()


def test_simulate_help_has_an_example() -> None:
    res = runner.invoke(app, ["simulate", "--help"])
    assert res.exit_code == 0, res.output
    assert "Example: wearpose simulate" in res.output and "--exclude-nc" in res.output


def test_simulate_without_a_store_fails_clearly(tmp_path: Path) -> None:
    res = runner.invoke(app, ["simulate", "--out", str(tmp_path / "o"), "--cache", str(tmp_path / "none"), "--json"])
    assert res.exit_code != 0
    assert "wearpose data prepare" in str(res.exception) or "prepare" in res.output


@pytest.mark.budget(25)  # two spawned workers: 10 s measured
@pytest.mark.corpus
def test_simulate_cli_two_workers_matches_one_process(tmp_path: Path, corpus_root: Path) -> None:
    cache, ids = make_mini_store(tmp_path / "corpus", corpus_root)
    out = tmp_path / "cli"
    res = runner.invoke(app, ["simulate", "--kit", "em6", "--split", "all", "--out", str(out), "--cache", str(cache),
                              "--seed", "3", "--workers", "2", "--limit", "2", "--json"])
    assert res.exit_code == 0, res.output
    r = json.loads(res.stdout[res.stdout.index("{"):])
    assert (r["simulated"], r["failed"], r["workers"]) == (2, 0, 2)
    assert r["clips_per_s"] > 0 and r["sensor_frames_per_s"] > 0
    index = json.loads((out / "index.json").read_text())
    assert sorted(index["clips"]) == ids[:2]
    # the same clips in this process: bit-identical files (seeds come from the clip ids, one
    # torch thread everywhere)
    ref = tmp_path / "ref"
    simulate_corpus(ref, "em6", None, cache_dir=cache, seed=3, limit=2, workers=1, progress=False)
    for row in index["clips"].values():
        a, b = np.load(out / row["file"]), np.load(ref / row["file"])
        assert sorted(a.files) == sorted(b.files)
        assert all(np.array_equal(a[k], b[k], equal_nan=a[k].dtype.kind == "f") for k in a.files)
        assert load_recording(out / row["file"]).names == ("back", "head", "right_lower_arm", "right_lower_leg",
                                                            "left_lower_arm", "left_lower_leg")
