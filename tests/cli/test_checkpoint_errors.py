"""A damaged or foreign ``.pt`` given as weights: one line naming the file, the problem and the
expected form -- not torch's several lines of zip/pickle internals."""

from __future__ import annotations

import pickle
from pathlib import Path

import pytest
import torch

from tests.cli.test_errors import em_file, run_main  # noqa: F401 - em_file is a fixture
from wearpose.errors import InputFileError
from wearpose.estimators.checkpoint import load_checkpoint
from wearpose.weights import weight_path


def _files(tmp: Path) -> dict[str, tuple[Path, str]]:
    good = weight_path("empose12_cpu").read_bytes()
    out = {}
    (tmp / "trunc.pt").write_bytes(good[: len(good) // 3])
    out["truncated"] = (tmp / "trunc.pt", "truncated or damaged torch archive")
    (tmp / "text.pt").write_text("hello\n")
    out["text"] = (tmp / "text.pt", "not a torch checkpoint (no zip archive; the file starts with b'hello")
    (tmp / "empty.pt").write_bytes(b"")
    out["empty"] = (tmp / "empty.pt", "empty file (0 bytes)")
    (tmp / "pickle.pt").write_bytes(pickle.dumps({"a": 1}))
    out["pickle"] = (tmp / "pickle.pt", "a pickle / legacy torch file")
    torch.save(torch.zeros(3), tmp / "tensor.pt")
    out["tensor"] = (tmp / "tensor.pt", "not a wearpose checkpoint (a torch file holding a Tensor)")
    return out


def test_load_checkpoint_names_the_problem_in_one_line(tmp_path: Path) -> None:
    for what, (path, problem) in _files(tmp_path).items():
        with pytest.raises(InputFileError) as ei:
            load_checkpoint(path)
        msg = str(ei.value)
        assert str(path) in msg and problem in msg and "written by `wearpose train`" in msg, (what, msg)
        assert "\n" not in msg and "miniz" not in msg and len(msg) - len(str(path)) < 400, (what, msg)


def test_estimate_with_a_truncated_checkpoint_is_one_error_line(em_file: Path, tmp_path: Path, capsys,  # noqa: F811
                                                                monkeypatch) -> None:
    bad = _files(tmp_path)["truncated"][0]
    code, err = run_main(["estimate", str(em_file), "--model", str(bad), "--out", str(tmp_path / "p.bvh")],
                         capsys, monkeypatch)
    assert code == 1 and err.startswith(f"error: {bad}: truncated or damaged torch archive"), err
    assert err.count("error:") == 1 and "miniz" not in err and "Expected: a .pt checkpoint" in err
