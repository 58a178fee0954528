"""simulate_corpus on Ray (optional extra): same recordings as the local executor; a clear error without Ray."""

from __future__ import annotations

import importlib.util
import sys

import numpy as np
import pytest

from tests.recording.dataset_testutils import make_mini_store
from wearpose.errors import ConfigError
from wearpose.recording.dataset import load_index, simulate_corpus


def test_ray_executor_without_ray_names_the_extra(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # makes `import ray` raise ImportError
    with pytest.raises(ConfigError, match=r"wearpose\[ray\]"):
        simulate_corpus(tmp_path / "out", "em12", None, cache_dir=tmp_path / "nothing", executor="ray", progress=False)
    with pytest.raises(ConfigError, match="executor must be one of"):
        simulate_corpus(tmp_path / "out", "em12", None, cache_dir=tmp_path / "nothing", executor="dask", progress=False)


@pytest.mark.corpus
@pytest.mark.skipif(importlib.util.find_spec("ray") is None, reason="Ray is an optional extra (pip install 'wearpose[ray]')")
def test_ray_executor_writes_the_same_recordings_as_the_local_one(tmp_path, monkeypatch, corpus_root):
    import ray

    monkeypatch.setenv("RAY_AUTH_MODE", "disabled")  # local test cluster: no token file
    cache, ids = make_mini_store(tmp_path / "corpus", corpus_root)
    local = simulate_corpus(tmp_path / "local", "imu6", None, cache_dir=cache, seed=3, workers=1, progress=False)
    try:
        res = simulate_corpus(tmp_path / "ray", "imu6", None, cache_dir=cache, seed=3, workers=2, executor="ray",
                              progress=False)
    finally:
        ray.shutdown()
    assert res["executor"] == "ray" and res["workers"] == 2 and res["simulated"] == local["simulated"] == len(ids)
    a, b = load_index(tmp_path / "local"), load_index(tmp_path / "ray")
    assert a["settings"] == b["settings"] and sorted(a["clips"]) == sorted(b["clips"])
    for cid, row in a["clips"].items():
        with np.load(tmp_path / "local" / row["file"]) as fa, np.load(tmp_path / "ray" / b["clips"][cid]["file"]) as fb:
            assert sorted(fa.files) == sorted(fb.files)
            for k in fa.files:
                assert np.array_equal(fa[k], fb[k]), (cid, k)
