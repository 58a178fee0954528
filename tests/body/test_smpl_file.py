"""A user's SMPL / SMPL-H file: written here in the official layouts, read without chumpy."""

from __future__ import annotations

import pickle
import sys
import types
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse
import torch

from tests.conftest import make_tiny_asset
from wearpose.body import BodyModel, load_smpl_file
from wearpose.body.skeleton import PARENTS
from wearpose.errors import ConfigError, InputFileError


class _FakeCh:
    """Pickles like a chumpy ``Ch``: global ``chumpy.ch.Ch`` with its array in state['x']."""

    def __init__(self, x: np.ndarray) -> None:
        self.x = x

    def __getstate__(self) -> dict:
        return {"x": self.x}


def _smpl_dict(num_joints: int = 24, posedirs: bool = True) -> dict:
    a = make_tiny_asset(seed=3, num_betas=10, posedirs=False)
    V = a.v_template.shape[0]
    rng = np.random.default_rng(5)
    weights, J_reg = a.weights.astype(np.float64), a.J_regressor.astype(np.float64)
    parents = list(PARENTS)
    if num_joints > 24:  # SMPL-H: 28 extra finger joints, 14 per hand, chains from the wrists
        extra = num_joints - 24
        for k in range(extra):
            wrist = 20 if k < extra // 2 else 21
            parents.append(wrist if k % 3 == 0 else 24 + k - 1)
        w_extra = np.zeros((V, extra))
        for v in range(V):  # give wrist-region vertices some finger weight
            if weights[v, 20] > 0.5:
                w_extra[v, 0] = 0.3
                weights[v, 20] -= 0.3
        weights = np.concatenate([weights, w_extra], axis=1)
        J_reg = np.concatenate([J_reg, np.full((extra, V), 1.0 / V)], axis=0)
    kintree = np.array([[4294967295] + parents[1:], list(range(num_joints))], dtype=np.int64)
    d = {
        "v_template": a.v_template.astype(np.float64), "f": a.faces.astype(np.uint32),
        "shapedirs": rng.normal(scale=0.01, size=(V, 3, 16 if num_joints > 24 else 10)),
        "J_regressor": scipy.sparse.csc_matrix(J_reg), "weights": weights, "kintree_table": kintree,
    }
    if posedirs:
        d["posedirs"] = rng.normal(scale=0.001, size=(V, 3, (num_joints - 1) * 9))
    return d


def _write_pkl_with_chumpy(path: Path, d: dict) -> None:
    """Pickle like the official files: shapedirs/v_template wrapped in chumpy objects."""
    mod = types.ModuleType("chumpy.ch")
    _FakeCh.__module__, _FakeCh.__qualname__ = "chumpy.ch", "Ch"
    mod.Ch = _FakeCh
    sys.modules["chumpy"] = types.ModuleType("chumpy")
    sys.modules["chumpy.ch"] = mod
    try:
        d = dict(d, shapedirs=_FakeCh(d["shapedirs"]), v_template=_FakeCh(d["v_template"]))
        with open(path, "wb") as fh:
            pickle.dump(d, fh, protocol=2)
    finally:
        del sys.modules["chumpy"], sys.modules["chumpy.ch"]
    assert "chumpy" not in sys.modules


def test_reads_official_pkl_layout_without_chumpy(tmp_path: Path) -> None:
    d = _smpl_dict()
    path = tmp_path / "SMPL_NEUTRAL.pkl"
    _write_pkl_with_chumpy(path, d)
    a = load_smpl_file(path)
    np.testing.assert_allclose(a.v_template, d["v_template"], atol=1e-6)
    np.testing.assert_allclose(a.shapedirs, d["shapedirs"], atol=1e-6)
    np.testing.assert_allclose(a.J_regressor, d["J_regressor"].toarray(), atol=1e-6)
    assert tuple(a.parents) == PARENTS
    # posedirs converted from the official (V, 3, 207) to the (207, V*3) layout
    np.testing.assert_allclose(a.posedirs, d["posedirs"].reshape(-1, 207).T, atol=1e-6)
    body = BodyModel(path, dtype=torch.float64)
    out = body(torch.zeros(72, dtype=torch.float64))
    np.testing.assert_allclose(out.vertices.numpy(), d["v_template"], atol=1e-6)


def test_reads_npz_and_env_variable(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    d = _smpl_dict()
    d["J_regressor"] = d["J_regressor"].toarray()
    path = tmp_path / "SMPL_MALE.npz"
    np.savez(path, **d)
    monkeypatch.setenv("WEARPOSE_SMPL_MODEL", str(path))
    body = BodyModel("smpl", dtype=torch.float64)
    assert body.asset_id == "smpl-file:SMPL_MALE.npz"
    betas = torch.randn(10, dtype=torch.float64)
    out = body(betas=betas)
    v = d["v_template"] + np.einsum("vcs,s->vc", d["shapedirs"], betas.numpy())
    np.testing.assert_allclose(out.vertices.numpy(), v, atol=1e-5)


def test_smplh_fingers_fold_into_wrists(tmp_path: Path) -> None:
    d = _smpl_dict(num_joints=52)
    path = tmp_path / "SMPLH_FEMALE.pkl"
    with open(path, "wb") as fh:
        pickle.dump(d, fh)
    a = load_smpl_file(path, num_betas=10)
    assert a.weights.shape[1] == 24 and a.shapedirs.shape[2] == 10
    np.testing.assert_allclose(a.weights.sum(1), 1.0, atol=1e-6)
    full = d["weights"]
    np.testing.assert_allclose(a.weights[:, 20], full[:, 20] + full[:, 24], atol=1e-6)


def test_missing_and_malformed_files(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    with pytest.raises(InputFileError, match=r"nope\.pkl.*file not found.*Expected: an SMPL"):
        load_smpl_file(tmp_path / "nope.pkl")
    bad = tmp_path / "garbage.pkl"
    bad.write_bytes(b"not a pickle at all")
    with pytest.raises(InputFileError, match=r"garbage\.pkl.*cannot be read"):
        load_smpl_file(bad)
    d = _smpl_dict()
    del d["weights"]
    p = tmp_path / "noweights.pkl"
    with open(p, "wb") as fh:
        pickle.dump(d, fh)
    with pytest.raises(InputFileError, match=r"noweights\.pkl \[weights\]: missing key"):
        load_smpl_file(p)
    d = _smpl_dict()
    d["shapedirs"] = d["shapedirs"][:10]
    p = tmp_path / "badshape.pkl"
    with open(p, "wb") as fh:
        pickle.dump(d, fh)
    with pytest.raises(InputFileError, match=r"\[shapedirs\]"):
        load_smpl_file(p)
    evil = tmp_path / "evil.pkl"
    evil.write_bytes(pickle.dumps({"x": print}))
    with pytest.raises(InputFileError, match="refusing to load global"):
        load_smpl_file(evil)
    monkeypatch.delenv("WEARPOSE_SMPL_MODEL", raising=False)
    with pytest.raises(ConfigError, match="WEARPOSE_SMPL_MODEL"):
        load_smpl_file(None)
