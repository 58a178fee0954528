"""Fixtures for calibration tests: the embedded body asset in float64 (real skin-site normals)."""

from __future__ import annotations

import pytest
import torch

from wearpose.body import BodyModel


@pytest.fixture(scope="session")
def body() -> BodyModel:
    return BodyModel(dtype=torch.float64)


@pytest.fixture(autouse=True)
def _one_thread(one_torch_thread):  # noqa: ARG001 - the shared fixture does the work
    yield
