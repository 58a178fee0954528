"""Rich tables at 80 columns fold long file and clip names onto more lines, never cut them with
"…" (issue 22: "wave_... skele..."): three commands whose tables carry long names."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tests.cli.test_cmd_recording import _write_tc
from tests.cli.test_errors import _simulated
from wearpose.cli import app
from wearpose.cli.app import console
from wearpose.recording import save_recording

runner = CliRunner()
LONG = "wave_hello_skeleton_take_01_left_handed_subject_with_a_long_descriptive_name"


@pytest.fixture
def narrow(monkeypatch) -> None:
    """The CLI's console at 80 columns (it reads COLUMNS once, at import)."""
    monkeypatch.setattr(console, "_width", 80)


def _check(res, *names: str) -> None:
    assert res.exit_code == 0, res.output
    assert "…" not in res.output, res.output
    assert max(len(line) for line in res.output.splitlines()) <= 80, res.output
    flat = "".join(ch for ch in res.output if ch.isalnum())  # folded cells, borders dropped
    for name in names:  # the last fold of each name survives (an ellipsis would have cut it)
        assert "".join(ch for ch in name if ch.isalnum())[-12:] in flat, (name, res.output)


def test_recording_import_table_folds_file_names(narrow, tmp_path: Path) -> None:
    p = tmp_path / f"{LONG}_Xsens.sensors"
    _write_tc(p)
    res = runner.invoke(app, ["recording", "import", "totalcapture", str(p), "--out", str(tmp_path / "o")])
    _check(res, p.name)


def test_estimate_table_folds_recording_and_output_paths(narrow, tmp_path: Path) -> None:
    rec = tmp_path / f"{LONG}.npz"
    save_recording(_simulated("em12", T=30, rate=30.0), rec)
    out = tmp_path / f"{LONG}_estimate.bvh"
    res = runner.invoke(app, ["estimate", str(rec), "--model", "empose12_cpu", "--out", str(out)])
    _check(res, str(rec), str(out), str(out) + ".json")


def test_calibrate_table_folds_the_written_path(narrow, tmp_path: Path) -> None:
    rec = tmp_path / f"{LONG}.npz"
    save_recording(_simulated("em12", T=30, rate=30.0), rec)
    out = tmp_path / f"{LONG}_calibration.json"
    res = runner.invoke(app, ["calibrate", str(rec), "--method", "empose-offsets", "--out", str(out)])
    _check(res, str(out))
    assert json.loads(out.read_text())["method"] == "empose-offsets"
