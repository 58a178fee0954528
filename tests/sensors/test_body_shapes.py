"""Bodies of every size (issue 23.6): a clip simulated on short and tall wearers drawn from the
asset's shape space, the motion re-fitted to each body."""

from __future__ import annotations

import pytest
import torch

from wearpose.body import BodyModel
from wearpose.body.kinematics import forward_kinematics
from wearpose.body.shapes import BETA_LIMIT, sample_betas
from wearpose.body.skeleton import JOINT_INDEX
from wearpose.evaluate import stance_foot_speed
from wearpose.motion import CorpusStore, refit_to_body
from wearpose.sensors import random_body_shape, simulate

CLIP = "bandai/bandai-B/dataset-2_walk_feminine_003"  # in the session store (tests/conftest.py)
FEET = [JOINT_INDEX["left_foot"], JOINT_INDEX["right_foot"]]


def test_sample_betas_is_seeded_and_truncated() -> None:
    draws = torch.stack([sample_betas(torch.Generator().manual_seed(s)) for s in range(400)])
    assert draws.shape == (400, 10) and float(draws.abs().max()) <= BETA_LIMIT
    assert abs(float(draws.mean())) < 0.05 and 0.85 < float(draws.std()) < 1.05  # N(0, 1), a little truncated
    assert torch.equal(random_body_shape(7), random_body_shape(7))
    assert not torch.equal(random_body_shape(7), random_body_shape(8))


@pytest.mark.corpus
@pytest.mark.budget(40)
def test_short_and_tall_wearers_keep_their_feet_on_the_floor_and_still(corpus_store) -> None:
    """beta[0] = -2 (1.47 m) and +2 (1.91 m): the soles stay on the floor (median lowest skin
    point within 2 cm of y = 0, never 2 cm below it in 90 % of the frames), planted feet move
    < 0.03 m/s in mid-stance, and the root travels as far as each body's legs reach."""
    body = BodyModel()
    clip = CorpusStore(corpus_store).load(CLIP)
    assert float(clip.betas.abs().max()) == 0.0
    # The corpus clip itself (beta = 0, converter motion-4: travel from the planted feet).
    _, J0 = forward_kinematics(clip.pose.double(), body.rest_joints().double())
    assert stance_foot_speed((J0 + clip.trans.double()[:, None])[:, FEET], clip.fps).median <= 0.03
    travel = {}
    for b0 in (-2.0, 2.0):
        betas = torch.zeros(10)
        betas[0] = b0
        with torch.no_grad():
            res = simulate(clip, "imu6", body, seed=3, noise="none", shape=betas)
        m = res.motion
        assert m is not None and torch.equal(m.betas, betas) and res.meta["betas"][0] == b0
        assert torch.equal(m.pose, clip.pose)  # rotations kept, only the root is re-fitted
        low = body.lowest_height(m.pose, m.betas, m.trans)
        assert abs(float(low.median())) <= 0.02 and float(low.quantile(0.1)) >= -0.02, (b0, low.median(), low.quantile(0.1))
        _, J = forward_kinematics(m.pose.double(), body.rest_joints(betas).double())
        st = stance_foot_speed((J + m.trans.double()[:, None])[:, FEET], m.fps)
        assert st.stances >= 8 and st.median <= 0.03, (b0, st.median)
        travel[b0] = float((m.trans[-1] - m.trans[0])[[0, 2]].norm())
    # The tall wearer covers more ground with the same steps (legs ~ 30 % longer).
    assert 1.2 < travel[2.0] / travel[-2.0] < 1.5, travel


def test_default_shape_is_the_motions_own(body_all_sites) -> None:
    """shape=None simulates the motion as given (no re-fit, same streams as before the option);
    the motion's own shape re-fits to itself; another shape changes the streams."""
    from sensor_testutils import smooth_motion  # noqa: PLC0415

    m = smooth_motion(T=120)
    a = simulate(m, "imu6", body_all_sites, seed=1)
    b = simulate(m, "imu6", body_all_sites, seed=1, shape=None)
    assert a.motion is None and "betas" not in a.meta
    assert all(torch.equal(a[n].acceleration, b[n].acceleration) for n in a.kit.sensor_names)
    same = refit_to_body(m, body_all_sites, m.betas.clone())
    assert torch.allclose(same.trans.double(), m.trans.double(), atol=1e-5)
    c = simulate(m, "imu6", body_all_sites, seed=1, shape="random")
    assert c.motion is not None and torch.equal(c.motion.betas, random_body_shape(1))
    first = a.kit.sensor_names[0]
    assert not torch.allclose(c[first].acceleration, a[first].acceleration)


def test_heldout_wearers_are_another_stream() -> None:
    """Evaluation wearers ("heldout") come from a stream no training draw uses: for the same clip
    seed they differ from the training wearer, and no heldout draw repeats a training draw."""
    train = torch.stack([random_body_shape(s) for s in range(200)])
    held = torch.stack([random_body_shape(s, draw="heldout") for s in range(200)])
    assert not torch.isclose(train[:, None], held[None]).all(-1).any()
    with pytest.raises(Exception, match="heldout"):
        random_body_shape(0, draw="test")
