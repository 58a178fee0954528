"""The offline HTML page carries a mesh skinned exactly like BodyModel."""

from __future__ import annotations

import base64
import json
import re
import time
from pathlib import Path

import numpy as np
import pytest
import torch

from tests.conftest import make_tiny_asset
from tests.viewer.chromium import CHROMIUM, Browser
from wearpose.body import BodyModel
from wearpose.errors import ShapeError
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


def _payload(path: Path) -> dict:
    return json.loads(re.search(r"const P = (\{.*?\});\n", path.read_text()).group(1))


def test_tracks_have_distinct_colours_and_a_legend(tmp_path: Path) -> None:
    from wearpose.viewer.scene import ESTIMATE_COLOUR, TRUTH_COLOUR

    body = BodyModel(make_tiny_asset())
    pose = torch.eye(3).expand(3, 24, 3, 3)
    trans = torch.zeros(3, 3)
    path = write_html(tmp_path / "v.html", body, pose, torch.zeros(10), trans, fps=30.0, label="estimate",
                      compare=[("ground truth", pose, torch.zeros(10), trans)], colours=[ESTIMATE_COLOUR, TRUTH_COLOUR],
                      site_names=["head"], sites_label="1 EM sensor (kitname)")
    p = _payload(path)
    assert [tuple(t["colour"]) for t in p["tracks"]] == [ESTIMATE_COLOUR, TRUTH_COLOUR]
    assert p["sites_label"] == "1 EM sensor (kitname)" and p["site_names"] == ["head"]
    html = path.read_text()
    assert '<span id="legend">' in html and "tr.col" in html  # the legend element; meshes shaded in their track's colour
    # Default colours differ too; a caller cannot give two tracks one colour.
    p2 = _payload(write_html(tmp_path / "d.html", body, pose, torch.zeros(10), trans, fps=30.0,
                             compare=[("b", pose, torch.zeros(10), trans), ("c", pose, torch.zeros(10), trans)]))
    assert len({tuple(t["colour"]) for t in p2["tracks"]}) == 3
    with pytest.raises(ShapeError, match="differ in colour"):
        write_html(tmp_path / "x.html", body, pose, torch.zeros(10), trans, fps=30.0,
                   compare=[("gt", pose, torch.zeros(10), trans)], colours=[TRUTH_COLOUR, TRUTH_COLOUR])


def test_no_sites_when_none_are_named(tmp_path: Path) -> None:
    body = BodyModel(make_tiny_asset())
    pose = torch.eye(3).expand(2, 24, 3, 3)
    p = _payload(write_html(tmp_path / "v.html", body, pose, torch.zeros(10), torch.zeros(2, 3), fps=30.0, site_names=()))
    assert p["sites"] == [] and p["site_names"] == []


@pytest.mark.parametrize("kit", ["em12", "em6", "imu6", "mimu6", "miposer"])
def test_kit_sites_are_the_kits_sensors(kit: str) -> None:
    from wearpose.sensors import get_kit, resolve_sites
    from wearpose.viewer.scene import kit_sites

    body = BodyModel()
    k = get_kit(kit)
    sites = kit_sites(kit, body)
    resolved, _ = resolve_sites(k, body.site_names, body.asset_id)
    assert set(sites) == {resolved[s.name] for s in k.sensors} and len(sites) == len(set(sites))
    assert len(sites) < len(body.site_names)  # not every site of the asset
    first = k.sensors[0].name
    assert kit_sites(kit, body, [first]) == (resolved[first],)


@pytest.mark.skipif(CHROMIUM is None, reason="no chromium/chrome executable found (set WEARPOSE_CHROMIUM)")
@pytest.mark.budget(30)
def test_page_draws_estimate_and_truth_in_their_colours_in_headless_chromium(tmp_path: Path) -> None:
    """The page's script runs (legend filled, a frame drawn) and both bodies show their own colour."""
    from wearpose.viewer.scene import ESTIMATE_COLOUR, TRUTH_COLOUR

    body = BodyModel()
    pose = torch.eye(3).expand(3, 24, 3, 3).clone()
    trans = torch.zeros(3, 3)
    path = write_html(tmp_path / "v.html", body, pose, torch.zeros(10), trans, fps=30.0, label="estimate",
                      compare=[("ground truth", pose, torch.zeros(10), trans)], colours=[ESTIMATE_COLOUR, TRUTH_COLOUR],
                      site_names=["head", "left_wrist"], sites_label="2 EM sensors (test)")
    browser = Browser(path.as_uri())
    try:
        t0, state = time.time(), None
        while time.time() - t0 < 20:
            state = browser.call("Runtime.evaluate", returnByValue=True, expression=(
                "[document.getElementById('legend').innerText, document.getElementById('c').dataset.frame]"))["result"].get("value")
            if state and int(state[1]) >= 0:
                break
            time.sleep(0.5)
        assert state and int(state[1]) >= 0, f"the page drew no frame (a script error?): {state}"
        assert state[0].split("\n") == ["estimate", "ground truth", "2 EM sensors (test)"]
        img = browser.screenshot().astype(int)
    finally:
        browser.close()
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    blue = (b > r + 60) & (b > 100)  # the estimate's shaded blue
    grey = (abs(r - g) < 10) & (abs(g - b) < 12) & (r > 90)  # the truth's shaded grey (the floor is darker)
    # The estimate stands left of the truth (+X is to the right from the default camera).
    assert blue.sum() > 500 and grey.sum() > 500, (blue.sum(), grey.sum())
    assert np.nonzero(blue)[1].mean() < np.nonzero(grey)[1].mean()
