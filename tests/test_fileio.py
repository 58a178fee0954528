"""wearpose.fileio: atomic writes leave either the old file or the whole new one, never a
temporary file beside it, and concurrent writers of one path never share a temporary file."""

from __future__ import annotations

import threading
from pathlib import Path

import pytest
import torch

from wearpose.fileio import atomic_savez, atomic_torch_save, atomic_write_text


def test_atomic_torch_save_round_trips_and_leaves_no_temporary(tmp_path: Path) -> None:
    path = tmp_path / "cache" / "train.pt"
    atomic_torch_save(path, {"x": torch.arange(5), "ids": ["a", "b"]})
    d = torch.load(path, weights_only=True)
    assert d["ids"] == ["a", "b"] and torch.equal(d["x"], torch.arange(5))
    assert [p.name for p in path.parent.iterdir()] == ["train.pt"]


def test_concurrent_writers_of_one_path_each_write_a_whole_file(tmp_path: Path) -> None:
    """Two torchrun ranks building the same data cache (issue 21: a shared ``.tmp`` name raced)."""
    path = tmp_path / "split.pt"
    errors: list[BaseException] = []

    def write(k: int) -> None:
        try:
            for _ in range(5):
                atomic_torch_save(path, {"x": torch.full((20000,), k)})
        except BaseException as exc:  # noqa: BLE001 - reported below
            errors.append(exc)

    threads = [threading.Thread(target=write, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
    x = torch.load(path, weights_only=True)["x"]
    assert x.shape == (20000,) and bool((x == x[0]).all())  # one writer's whole file
    assert [p.name for p in tmp_path.iterdir()] == ["split.pt"]


def test_a_failed_write_keeps_the_old_file(tmp_path: Path) -> None:
    path = tmp_path / "a.txt"
    atomic_write_text(path, "old")

    class Boom:
        def __reduce__(self):
            raise RuntimeError("cannot pickle")

    with pytest.raises(Exception, match="cannot pickle"):
        atomic_torch_save(path, {"x": Boom()})
    assert path.read_text() == "old" and [p.name for p in tmp_path.iterdir()] == ["a.txt"]
    atomic_savez(tmp_path / "b.npz", {"y": torch.arange(3).numpy()})
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "b.npz"]
