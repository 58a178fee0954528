"""Body shapes drawn from an asset's shape space: the wearers of simulated recordings.

The distribution (:func:`sample_betas`): every shape coefficient independently standard normal,
truncated at ``+-limit`` (default 2.5) standard deviations by redrawing. On the embedded asset
(``wearpose-anny-v1``) this is the population the shape space was fitted to: 10 PCA components
of 400 sampled adult anny phenotypes (age 20-70, both sexes, height, weight, muscle and
proportions from anny's age-conditional distributions; ``tools/build_body_asset.py``), one unit
= one standard deviation of that sample, so N(0, 1) per component has the sample's mean and
variance (the sample is not exactly Gaussian: sex makes ``beta[0]`` bimodal; the normal is the
documented approximation). ``beta[0]`` carries 94 % of the variance and mixes height and sex:
1.47 m at -2, 1.69 m at 0, 1.91 m at +2 (docs/body.md). The truncation keeps every wearer within
about 1.4-2.0 m. On a user's SMPL file the same draw follows SMPL's CAESAR PCA, also in units
of one standard deviation.

Seeding: callers draw from a generator seeded per clip (the simulator's
:func:`wearpose.sensors.random_body_shape` uses the clip's simulation seed with its own stream
key), so a clip's wearer is reproducible and the seed namespaces that keep evaluation draws
apart from training draws keep evaluation bodies apart too.

Height (:func:`standing_height`): the body at zero pose (SMPL's T-pose, arms horizontal),
highest skin point minus lowest (crown of the head minus the soles), the measure the asset's
build reports against ``beta[0]`` (``tools/build_body_asset.py``).
"""

from __future__ import annotations

import torch

from typing import Any

from wearpose.errors import ConfigError

#: Default truncation of :func:`sample_betas`, standard deviations.
BETA_LIMIT = 2.5


def sample_betas(generator: torch.Generator, num_betas: int = 10, limit: float = BETA_LIMIT,
                 dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """One body shape ``(num_betas,)``: independent N(0, 1) coefficients truncated at ``+-limit``
    (entries beyond it are redrawn from the same generator). See the module doc for what this
    distribution is on each asset."""
    if num_betas < 1:
        raise ConfigError(f"sample_betas: num_betas = {num_betas}; expected at least 1")
    if not limit > 0.5:
        raise ConfigError(f"sample_betas: limit = {limit!r} standard deviations; expected more than 0.5")
    b = torch.randn(num_betas, generator=generator, dtype=torch.float64)
    while bool((out := b.abs() > limit).any()):
        b[out] = torch.randn(int(out.sum()), generator=generator, dtype=torch.float64)
    return b.to(dtype)


def zero_pose_vertices(body: Any, betas: torch.Tensor) -> torch.Tensor:
    """The skin of ``body`` at zero pose (T-pose), zero translation: ``(..., V, 3)`` m, model
    frame (Y up), for betas ``(..., S)``."""
    with torch.no_grad():
        return body(None, torch.as_tensor(betas).to(device=body.device, dtype=body.dtype), None).vertices


def standing_height(body: Any, betas: torch.Tensor) -> torch.Tensor:
    """Standing height of the body of ``betas`` ``(..., S)`` (module doc): ``(...)`` m, the
    vertical extent of its zero-pose skin (:func:`zero_pose_vertices`)."""
    y = zero_pose_vertices(body, betas)[..., 1]
    return y.amax(-1) - y.amin(-1)


__all__ = ["BETA_LIMIT", "sample_betas", "standing_height", "zero_pose_vertices"]
