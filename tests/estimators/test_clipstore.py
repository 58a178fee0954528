"""The shared clip store (wearpose.estimators.clipstore): concatenation, per-clip tensors, the
clip column, the cache round trip."""

from pathlib import Path

import torch

from wearpose.estimators.clipstore import cached_clips, concat_clips


def _clip(T: int, c: float) -> dict[str, torch.Tensor]:
    return {"x": torch.full((T, 2), c), "m": torch.arange(T) % 2 == 0, "b": torch.tensor([c, -c])}


def test_concat_clips_frames_clips_and_index():
    seen: list[tuple[int, int]] = []
    d = concat_clips([3, 1, 4], lambda T: _clip(T, float(T)), ("x", "m"), clip_keys=("b",), clip_column=True,
                     progress=lambda done, total: seen.append((done, total)))
    assert list(d) == ["x", "m", "clip", "b", "starts", "lengths"]
    assert d["x"].shape == (8, 2) and d["x"][:, 0].tolist() == [3, 3, 3, 1, 4, 4, 4, 4]
    assert d["m"].dtype == torch.bool and d["m"].tolist() == [True, False, True, True, True, False, True, False]
    assert d["clip"].tolist() == [0, 0, 0, 1, 2, 2, 2, 2] and d["clip"].dtype == torch.long
    assert d["b"].tolist() == [[3, -3], [1, -1], [4, -4]]
    assert d["starts"].tolist() == [0, 3, 4] and d["lengths"].tolist() == [3, 1, 4]
    assert seen == [(1, 3), (2, 3), (3, 3)]


def test_concat_clips_lazy_iterator_and_empty():
    seen: list[tuple[int, int]] = []
    d = concat_clips(iter([2, 2]), lambda T: _clip(T, 1.0), ("x",), total=2, progress=lambda *a: seen.append(a))
    assert "clip" not in d and d["lengths"].tolist() == [2, 2] and seen == [(1, 2), (2, 2)]
    e = concat_clips([], lambda T: _clip(T, 1.0), ("x",))
    assert e["x"].numel() == 0 and e["starts"].tolist() == [] and e["lengths"].dtype == torch.long


def test_cached_clips_builds_once_then_loads_the_same(tmp_path: Path):
    calls = []

    def build() -> dict[str, torch.Tensor]:
        calls.append(1)
        return concat_clips([2, 3], lambda T: _clip(T, 0.5), ("x", "m"), clip_column=True)

    path = tmp_path / "cache" / "train-0123.pt"
    a = cached_clips(path, ["a", "b"], "fp", build)
    b = cached_clips(path, ["a", "b"], "fp", build)
    assert calls == [1] and path.is_file()
    assert not list(path.parent.glob("*.tmp*"))  # written through a temporary file, none left over
    assert a["clip_ids"] == b["clip_ids"] == ["a", "b"] and a["fingerprint"] == b["fingerprint"] == "fp"
    for k in ("x", "m", "clip", "starts", "lengths"):
        assert torch.equal(a[k], b[k]) and a[k].dtype == b[k].dtype


def test_clip_data_counts_the_frames_of_its_clips():
    from dataclasses import dataclass

    from wearpose.estimators.clipstore import ClipData

    @dataclass(kw_only=True)
    class Split(ClipData):
        x: torch.Tensor

    d = concat_clips([3, 1, 4], lambda T: _clip(T, 1.0), ("x",))
    s = Split(x=d["x"], starts=d["starts"], lengths=d["lengths"], clip_ids=["a", "b", "c"], fingerprint="fp")
    assert s.num_frames == s.x.shape[0] == 8 and s.settings == {}
    empty = concat_clips([], lambda T: _clip(T, 1.0), ("x",))
    assert Split(x=empty["x"], starts=empty["starts"], lengths=empty["lengths"], clip_ids=[], fingerprint="").num_frames == 0


def test_split_source_ids_fingerprint_and_cache_folder(tmp_path: Path):
    from wearpose.estimators.checkpoint import fingerprint
    from wearpose.estimators.clipstore import split_source

    class Store:
        root = tmp_path / "store"

        def clips(self, split: str) -> list[str]:
            return [f"{split}/{i}" for i in range(5)]

    st = Store()
    s, ids, fp, root = split_source("val", {"k": 1}, "m", store=st, limit=2)
    assert s is st and ids == ["val/0", "val/1"] and root == tmp_path / "store" / "estimators" / "m"
    assert fp == fingerprint(ids, {"k": 1, "split": "val"})
    _, ids2, fp2, root2 = split_source("val", {"k": 1}, "m", store=st, cache_root=tmp_path / "c", clip_ids=("x", "y"))
    assert ids2 == ["x", "y"] and root2 == tmp_path / "c" and fp2 != fp
