"""Shared fixtures.  Kernel tests need an OpenCL device: CI installs PoCL, so a
missing device is a failure, never a skip."""

import numpy as np
import pytest


@pytest.fixture(scope="session")
def cc():
    from clwave.device.context import ComputeContext
    return ComputeContext.get("auto")


@pytest.fixture
def rng():
    return np.random.default_rng(12345)
