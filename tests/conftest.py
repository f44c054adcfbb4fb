"""Shared fixtures.  Kernel tests need an OpenCL device: CI installs PoCL, so a
missing device is a failure, never a skip."""

import os

import numpy as np
import pytest

# PoCL sizes its device from the host memory free when it starts (that less 2 GiB; a buffer a quarter of it rounded
# up to a power of two): 4 GiB a buffer on an idle 24 GB machine, 2 GiB where the page cache had filled, so a test that
# needed more than 2 GiB in one buffer passed or failed by luck.  A device of 6 GiB (2 GiB a buffer) wherever the host
# has that much, unless the environment names another: set before any test starts PoCL (docs/known-gaps.md §13)
os.environ.setdefault("POCL_MEMORY_LIMIT", "6")


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


@pytest.fixture
def dirty_memory(monkeypatch):
    """Every uninitialised device array (``pyopencl.array.empty``) has every bit set (NaN in floats), in it and for
    4 KiB past its end: what a buffer may hold in a process whose heap has been used (PoCL allocates from it; a fresh
    kernel build dirties it), where a test process most often gets fresh zero pages.  A render that reads what it never
    wrote then shows it."""
    import pyopencl as cl
    import pyopencl.array as cla

    empty = cla.empty

    def dirty(queue, shape, dtype, *args, **kw):
        shape = (int(shape),) if np.ndim(shape) == 0 else tuple(int(n) for n in shape)
        size, dtype = int(np.prod(shape)), np.dtype(dtype)
        out = empty(queue, size + 4096 // dtype.itemsize, dtype, *args, **kw)
        cl.enqueue_fill_buffer(queue, out.base_data, np.full(1, 255, np.uint8), 0, out.nbytes)
        return out[:size].reshape(shape)

    monkeypatch.setattr(cla, "empty", dirty)
