"""``wearpose calibrate``: runs a calibration on a recording file and stores the result with it."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from tests.sensors.sensor_testutils import smooth_motion
from wearpose.cli import app
from wearpose.recording import Recording, load_recording, save_recording

runner = CliRunner()


def test_calibrate_help_has_an_example() -> None:
    res = runner.invoke(app, ["calibrate", "--help"])
    assert res.exit_code == 0, res.output
    assert "Example: wearpose calibrate" in res.output


@pytest.fixture(scope="module")
def em_file(tmp_path_factory) -> tuple[Path, object]:
    """An em12 recording (1 s at 120 Hz, ideal sensors, a random subject's offsets) and its simulation."""
    from wearpose.body import BodyModel
    from wearpose.sensors import simulate

    m = smooth_motion(T=60, fps=60.0, seed=4, dtype=torch.float32)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = simulate(m, "em12", BodyModel(), seed=9, noise="none", offsets="random")
    path = tmp_path_factory.mktemp("cal") / "em.npz"
    save_recording(Recording.from_simulation(res, m), path)
    return path, res


def test_empose_offsets_stored_in_a_copy_and_as_json(em_file, tmp_path: Path) -> None:
    path, sim = em_file
    out = tmp_path / "calibrated.npz"
    res = runner.invoke(app, ["calibrate", str(path), "--method", "empose-offsets", "--out", str(out), "--json"])
    assert res.exit_code == 0, res.output
    payload = json.loads(res.stdout)
    assert payload["written"] == str(out) and payload["calibration"]["method"] == "empose-offsets"
    rec = load_recording(out)
    cal = rec.meta["calibration"]
    # noise-free simulation: the offsets come back (float32 file data, so ~1e-5 m)
    assert np.allclose(cal["translation"], sim.em_offsets.t.numpy(), atol=1e-4)
    assert np.allclose(cal["rotation"], sim.em_offsets.R.numpy(), atol=1e-3)
    assert rec.subject["offsets"]["sensors"] == list(sim.kit.sensor_names)
    assert "offsets_previous" in rec.subject  # the simulated truth is kept, not overwritten
    assert "calibration" not in load_recording(path).meta  # --out leaves the input alone
    js = tmp_path / "cal.json"
    res = runner.invoke(app, ["calibrate", str(path), "--method", "empose-offsets", "--out", str(js)])
    assert res.exit_code == 0, res.output
    assert json.loads(js.read_text())["format"] == "wearpose.calibration"


def test_in_place_default_and_errors(em_file, tmp_path: Path) -> None:
    path, _ = em_file
    copy = tmp_path / "copy.npz"
    copy.write_bytes(path.read_bytes())
    res = runner.invoke(app, ["calibrate", str(copy), "--method", "empose-offsets", "--window", "0.1", "0.9"])
    assert res.exit_code == 0, res.output
    cal = load_recording(copy).meta["calibration"]
    assert cal["params"]["window"] == [0.1, 0.9]
    res = runner.invoke(app, ["calibrate", str(copy), "--method", "magic"])
    assert res.exit_code != 0 and "empose-offsets" in str(res.exception)
    res = runner.invoke(app, ["calibrate", str(copy), "--method", "tpose"])  # an EM-only recording
    assert res.exit_code != 0 and "imu" in str(res.exception)
