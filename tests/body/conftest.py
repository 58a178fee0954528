"""Fixtures for the body-model tests."""

from __future__ import annotations

import pytest


@pytest.fixture(autouse=True)
def _one_thread(one_torch_thread):  # noqa: ARG001 - the shared fixture does the work
    # gradcheck runs thousands of tiny forwards: on a loaded 2-core machine two threads made it
    # 14x slower (15 s quiet, 201 s beside other work); one thread keeps it near its quiet time.
    yield
