"""tools/fvr.py (the Fourier volume rendering peer) against exact line integrals of a Gaussian blob."""

import sys
from pathlib import Path

import numpy as np
import pytest

import clwave

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
from fvr import FourierRenderer  # noqa: E402

SIGMA = 2.5                            # world units: well sampled, and negligible at the volume's faces
CENTRE = np.array([1.5, -2.0, 0.7])    # world (x, y, z)


def blob(shape, spacing, origin):
    """A Gaussian sampled at the voxel centres of docs/coordinates.md §1."""
    index = np.stack(np.meshgrid(*[np.arange(n) for n in shape], indexing="ij"), axis=-1)[..., ::-1]  # (x, y, z)
    world = np.asarray(origin) + (index - (np.array(shape[::-1]) - 1) / 2.0) * np.asarray(spacing[::-1])
    return clwave.Volume(np.exp(-np.sum((world - CENTRE) ** 2, axis=-1) / (2 * SIGMA ** 2)), spacing, origin)


def line_integrals(view):
    """The Gaussian's integral along each pixel's line: sqrt(2 pi) sigma exp(-d^2 / 2 sigma^2), d its distance."""
    d = view.pixel_centres() - CENTRE
    d -= (d @ view.n)[..., None] * view.n
    return np.sqrt(2 * np.pi) * SIGMA * np.exp(-np.sum(d ** 2, axis=-1) / (2 * SIGMA ** 2))


@pytest.mark.parametrize("shape, spacing, origin", [((32, 32, 32), (1.0, 1.0, 1.0), (0.5, -0.25, 0.3)),
                                                    ((40, 36, 48), (1.0, 1.2, 0.8), (0.0, 0.0, 0.0))])
def test_fourier_renderer_against_exact_line_integrals(shape, spacing, origin):
    vol = blob(shape, spacing, origin)
    renderer = FourierRenderer(vol)
    Gz, Gy, Gx = 2 * np.array(shape)
    assert renderer.nbytes == (Gz + 3) * (Gy + 3) * (Gx // 2 + 4) * 8   # the padded half spectrum, complex64
    for azimuth, elevation, size in ((30, 20, 64), (137.5, -40, (48, 63)), (0, 0, 64), (90, 90, 40)):
        camera = clwave.Camera(azimuth, elevation, size=size)
        image = renderer.render(camera)
        truth = line_integrals(camera.view(vol))
        assert image.shape == truth.shape and image.dtype == np.float32
        error = np.sqrt(np.sum((image - truth) ** 2) / np.sum(truth ** 2))
        assert error < 1e-3, (azimuth, elevation, error)
