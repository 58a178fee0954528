"""Body-shape error of an estimated shape (issue 24.5): standing height and zero-pose vertex error."""

from __future__ import annotations

import pytest
import torch

from wearpose.body import BodyModel
from wearpose.body.shapes import standing_height, zero_pose_vertices
from wearpose.errors import ShapeError
from wearpose.evaluate.metrics import shape_errors


@pytest.fixture(scope="module")
def body() -> BodyModel:
    return BodyModel()


def test_standing_height_is_the_assets_own_measure(body: BodyModel) -> None:
    """The one height definition reproduces what the asset build recorded against beta[0]
    (``tools/build_body_asset.py``: max y - min y of the T-posed skin)."""
    table = body.meta["shape_space"]["standing_height_m_vs_beta0"]
    b = torch.zeros(len(table), 10)
    b[:, 0] = torch.tensor([float(k) for k in table])
    h = standing_height(body, b)
    assert h.shape == (len(table),)
    assert h.tolist() == pytest.approx(list(table.values()), abs=1e-3)
    v = zero_pose_vertices(body, b[0])
    assert v.shape == (body.v_template.shape[0], 3)


def test_shape_errors_of_a_known_difference(body: BodyModel) -> None:
    true = torch.zeros(10)
    tall = torch.zeros(10)
    tall[0] = 1.0
    same = shape_errors(body, true, true)
    assert float(same.height_error) == 0.0 and float(same.zero_pose_vertex_error) == 0.0
    e = shape_errors(body, tall, true)
    # beta[0] = +1 is 10.85 cm taller on this asset (1.7994 vs 1.6909 m)
    assert float(e.height_difference) == pytest.approx(0.1085, abs=2e-3)
    assert float(e.height_error) == pytest.approx(float(e.height_difference))
    assert float(e.height_true) == pytest.approx(float(standing_height(body, true)))
    back = shape_errors(body, true, tall)
    assert float(back.height_difference) == pytest.approx(-float(e.height_difference), abs=1e-6)
    assert float(back.height_error) == pytest.approx(float(e.height_error), abs=1e-6)
    want = (zero_pose_vertices(body, tall) - zero_pose_vertices(body, true)).norm(dim=-1).mean()
    assert float(e.zero_pose_vertex_error) == pytest.approx(float(want), rel=1e-6)
    assert 0.01 < float(e.zero_pose_vertex_error) < 0.2  # a taller body: centimetres, not metres
    batch = shape_errors(body, torch.stack([true, tall]), true)  # broadcast over clips
    assert batch.height_error.shape == (2,) and float(batch.height_error[1]) == pytest.approx(float(e.height_error))
    with pytest.raises(ShapeError, match="betas_pred"):
        shape_errors(body, [0.0] * 10, true)
