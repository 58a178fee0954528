"""``wearpose bench latency``: one harness, the same keys for every method."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from wearpose.cli import app

KEYS = {"median_ms", "p99_ms", "max_ms", "calls"}


@pytest.mark.budget(20)
@pytest.mark.parametrize("model", ["pip_cpu", "birae6_cpu"])
def test_latency_of_a_model_on_a_procedural_clip(model: str, tmp_path: Path) -> None:
    res = CliRunner().invoke(app, ["bench", "latency", model, "--frames", "4", "--warmup", "1", "--json",
                                   "--out", str(tmp_path / "lat")])
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    assert set(out["online_ms"]) == KEYS and set(out["online_cpu_ms"]) == KEYS
    assert out["frames"] == 4 and out["online_ms"]["calls"] == 4
    assert 0 < out["online_ms"]["median_ms"] <= out["online_ms"]["p99_ms"] <= out["online_ms"]["max_ms"]
    assert out["frame_period_ms"] == pytest.approx(1000 / out["rate_hz"])
    assert out["reference"]["best_ms"] > 0 and len(out["machine"]["load_average"]) == 3
    assert json.loads((tmp_path / "lat.json").read_text())["model"] == model
    assert "| wall |" in (tmp_path / "lat.md").read_text()


def test_a_weight_free_model_without_kit_or_recording_is_refused() -> None:
    res = CliRunner().invoke(app, ["bench", "latency", "segments", "--frames", "2"])
    assert res.exit_code != 0 and "--kit" in str(res.exception)


def test_an_offline_only_model_is_refused_with_the_reason() -> None:
    res = CliRunner().invoke(app, ["bench", "latency", "segments", "--frames", "2", "--kit", "imu6"])
    assert res.exit_code != 0 and "offline only" in str(res.exception), res.exception


@pytest.mark.budget(40)
def test_a_baseline_checkout_is_timed_beside_on_the_same_frames(tmp_path: Path) -> None:
    """``--baseline SRC``: that checkout's code (here this one's, imported a second time beside it)
    steps the same frames interleaved; the same code gives the same rotations, and a setting it
    has (EM-POSE's N) is applied to both; ``--budget-hz`` sets the frame period compared with."""
    import wearpose

    src = Path(wearpose.__file__).resolve().parents[1]
    res = CliRunner().invoke(app, ["bench", "latency", "empose12_cpu", "--frames", "3", "--warmup", "1", "--json",
                                   "--set", "iterations=2", "--budget-hz", "120", "--baseline", str(src),
                                   "--out", str(tmp_path / "lat")])
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    b = out["baseline"]
    assert b["src"] == str(src) and b["settings"]["iterations"] == out["settings"]["iterations"] == 2
    assert set(b["online_ms"]) == KEYS and b["online_ms"]["calls"] == 3 and b["notes"] == []
    assert out["max_abs_diff_local_rot"] == 0.0
    assert out["speedup"]["median"] == pytest.approx(b["online_ms"]["median_ms"] / out["online_ms"]["median_ms"])
    assert out["frame_period_ms"] == pytest.approx(1000 / 120) and out["rate_hz"] == 30
    assert "speed-up (baseline / this)" in (tmp_path / "lat.md").read_text()
    assert wearpose.__file__.startswith(str(src)) and wearpose is __import__("wearpose")  # this version restored
