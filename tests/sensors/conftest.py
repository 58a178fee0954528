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
def _one_thread():
    # These tests run many tiny tensor ops; thread hand-offs dominate on a loaded machine.
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)
