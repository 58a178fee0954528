"""Fixtures for sensor tests."""

from __future__ import annotations

import pytest
import torch

from sensor_testutils import tiny_full_sites_asset
from tests.conftest import make_tiny_asset
from wearpose.body import BodyModel


@pytest.fixture(scope="session")
def body_all_sites() -> BodyModel:
    return BodyModel(tiny_full_sites_asset(), dtype=torch.float64)


@pytest.fixture(scope="session")
def body_tiny() -> BodyModel:
    return BodyModel(make_tiny_asset(), dtype=torch.float64)


@pytest.fixture(autouse=True)
def _one_thread(one_torch_thread):  # noqa: ARG001 - the shared fixture does the work
    yield
