"""The offline HTML page carries a mesh skinned exactly like BodyModel."""

from __future__ import annotations

import base64
import json
import re
from pathlib import Path

import numpy as np
import torch

from tests.conftest import make_tiny_asset
from wearpose.body import BodyModel
from wearpose.geometry import axis_angle_to_matrix
from wearpose.viewer import write_html


def test_page_skinning_matches_body_model(tmp_path: Path) -> None:
    body = BodyModel(make_tiny_asset())
    g = torch.Generator().manual_seed(0)
    T = 5
    pose = axis_angle_to_matrix(torch.randn(T, 24, 3, generator=g) * 0.4)
    betas = torch.randn(10, generator=g)
    trans = torch.randn(T, 3, generator=g)
    gt_pose = axis_angle_to_matrix(torch.randn(T, 24, 3, generator=g) * 0.4)
    path = write_html(tmp_path / "v.html", body, pose, betas, trans, fps=30.0, title="t", label="estimate",
                      compare=[("ground truth", gt_pose, betas, trans)])
    html = path.read_text()
    payload = json.loads(re.search(r"const P = (\{.*?\});\n", html).group(1))
    dec = lambda k, dt: np.frombuffer(base64.b64decode(payload[k]), dtype=dt)  # noqa: E731
    widx = dec("widx", "u1").reshape(-1, 4)
    w = dec("w", "<f4").reshape(-1, 4)
    assert [t["label"] for t in payload["tracks"]] == ["estimate", "ground truth"]
    for k, (p, shift) in enumerate(((pose, 0.0), (gt_pose, 1.0))):
        track = payload["tracks"][k]
        tdec = lambda key, dt: np.frombuffer(base64.b64decode(track[key]), dtype=dt)  # noqa: E731
        rest = tdec("verts", "<f4").reshape(-1, 3)
        A = tdec("A", "<f4").reshape(T, 24, 12)
        # Re-do in numpy what the page's JavaScript does, and compare with the model.
        M = A[:, widx]  # (T, V, 4, 12)
        pv = np.einsum("vk,tvkij,vj->tvi", w, M[..., :9].reshape(T, -1, 4, 3, 3), rest) + np.einsum("vk,tvki->tvi", w, M[..., 9:])
        ref = body(p, betas, trans).vertices.numpy()
        ref[..., 0] += shift  # the second track is drawn 1 m along +X
        # The tiny asset has at most 2 joints per vertex, so top-4 truncation is exact here.
        np.testing.assert_allclose(pv, ref, atol=1e-5)
    assert payload["T"] == T and payload["site_names"] == ["head", "left_forearm"]
