"""docs/formats.md lets someone write a valid recording by hand: run the document's example."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from wearpose.recording import load_recording

DOC = Path(__file__).resolve().parents[2] / "docs" / "formats.md"
MARKER = "<!-- worked-example"


def _example_code() -> str:
    text = DOC.read_text(encoding="utf-8")
    at = text.index(MARKER)
    m = re.compile(r"```python\n(.*?)```", re.S).search(text, at)
    assert m, "no ```python block after the worked-example marker"
    return m.group(1)


def test_worked_example_writes_a_valid_recording(tmp_path, monkeypatch):
    code = _example_code()
    assert "import wearpose" not in code and "from wearpose" not in code  # by hand, numpy only
    monkeypatch.chdir(tmp_path)
    exec(compile(code, str(DOC), "exec"), {"__name__": "formats_md_example"})
    rec = load_recording(tmp_path / "my_recording.npz")
    assert rec.names == ("left_forearm", "right_forearm") and rec.kinds == ("em6dof", "imu")
    imu = rec.sensor("left_forearm")
    assert imu.info.acc_unit == "g" and (~imu.valid).sum() == 3
    can = rec.to_canonical()
    acc = can.sensor("left_forearm").acceleration
    # At rest: raw +1 g reading becomes zero free acceleration in the Y-up world.
    np.testing.assert_allclose(acc[imu.valid], 0.0, atol=1e-5)
    grid = can.on_common_grid()
    assert grid.channels["orientation"].shape == (120, 2, 3, 3) and grid.all_valid.sum() == 117
    assert rec.subject == {"id": "p01", "height_m": 1.8}


def test_every_documented_sensor_field_exists():
    """The header table in the document lists exactly SensorInfo's fields."""
    from dataclasses import fields

    from wearpose.recording import SensorInfo

    text = DOC.read_text(encoding="utf-8")
    for f in fields(SensorInfo):
        assert f"| `{f.name}` |" in text, f"docs/formats.md does not document SensorInfo.{f.name}"


@pytest.mark.parametrize("channel", ["position", "orientation", "acceleration", "angular_velocity", "magnetic_field"])
def test_every_channel_documented(channel):
    assert f"`sensors/<name>/{channel}`" in DOC.read_text(encoding="utf-8")
