"""Fixtures shared by the estimator tests."""

from __future__ import annotations

import pytest

from wearpose.body import BodyModel


@pytest.fixture(autouse=True)
def _one_thread(one_torch_thread):  # noqa: ARG001 - the shared fixture does the work
    yield


@pytest.fixture(scope="session")
def body() -> BodyModel:
    return BodyModel()
