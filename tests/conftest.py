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


@pytest.fixture(scope="module")
def model_file(tmp_path_factory):
    """A small .clw file (hydrogen 16^3, cubic, 1 level, 20 % kept), for the tests that craft files from it."""
    import clwave

    path = tmp_path_factory.mktemp("clw") / "m.clw"
    clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", 16), "cubic", levels=1).threshold(keep=0.2).save(path)
    return path
