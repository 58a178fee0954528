"""Fixtures for calibration tests: the embedded body asset in float64 (real skin-site normals)."""

from __future__ import annotations

import pytest
import torch

from wearpose.body import BodyModel


@pytest.fixture(scope="session")
def body() -> BodyModel:
    return BodyModel(dtype=torch.float64)


@pytest.fixture(autouse=True)
def _one_thread():
    # Many small tensor ops: thread hand-offs dominate on a loaded machine.
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)
