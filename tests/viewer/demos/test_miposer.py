"""``wearpose demo --kit miposer`` with the shipped weights on a test clip (corpus)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest


def test_kit_dispatch() -> None:
    from wearpose.cli.demo import kit_demo
    from wearpose.viewer.demos.miposer import run_demo

    assert kit_demo("miposer") is run_demo


@pytest.mark.corpus
def test_demo_writes_timeline_viewer_and_metrics(tmp_path: Path, corpus_store: Path) -> None:
    pytest.importorskip("matplotlib")
    from wearpose.viewer.demos.miposer import run_demo
    from wearpose.weights import list_weights

    if "miposer_cpu" not in list_weights():
        pytest.skip("no shipped miposer_cpu weights")
    r = run_demo("cmu_daz/05/05_01", tmp_path, max_seconds=1.0)
    assert {"clip", "frames", "fps", "html", "title", "metrics"} <= set(r)
    assert Path(r["timeline"]).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "viewer.html" in Path(r["html"]).read_text() and Path(r["viewer"]).is_file()
    m = r["metrics"]
    assert all(k.endswith(("_cm", "_pct")) for k in m) and 0.0 < m["mpjpe_upper_mim_off_cm"] < 50.0
    assert json.loads((tmp_path / "metrics.json").read_text())["frames"] == r["frames"]
