"""Timing helpers of the benchmarks (wearpose.evaluate.latency)."""

from __future__ import annotations

from pathlib import Path

import pytest

from wearpose.evaluate.latency import import_baseline, latency_stats, reference_timing, time_calls


def test_latency_stats_and_interleaved_calls() -> None:
    s = latency_stats([0.001] * 99 + [0.101])
    assert s["calls"] == 100 and s["median_ms"] == pytest.approx(1.0) and s["max_ms"] == pytest.approx(101.0)
    assert 1.0 < s["p99_ms"] < 101.0
    order: list[str] = []
    t = time_calls({"a": lambda: order.append("a"), "b": lambda: order.append("b")}, repeats=2, warmup=0)
    assert order == ["a", "b", "a", "b"] and len(t["a"]) == 2


def test_reference_timing_reports_the_loop() -> None:
    r = reference_timing(repeats=1)
    assert r["best_ms"] > 0 and r["gflops"] > 0 and "float32" in r["loop"]


def test_import_baseline_loads_another_checkout_beside_this_one(tmp_path: Path) -> None:
    pkg = tmp_path / "src" / "wearpose"
    pkg.mkdir(parents=True)
    (pkg / "__init__.py").write_text("VERSION = 'old'\n")
    import wearpose

    old = import_baseline(tmp_path / "src", "wearpose")
    assert old.VERSION == "old" and not hasattr(wearpose, "VERSION")
    import sys

    assert sys.modules["wearpose"] is wearpose  # this checkout stays loaded
    with pytest.raises(FileNotFoundError, match="no wearpose/ package folder"):
        import_baseline(tmp_path, "wearpose")
