"""Issues #30, #31 and #33 on inputs no other test holds (twenty-first session): data scales far from 1, prime and
non-cubic shapes, anisotropic CT spacing, against independent answers.  Each test pins a case that once broke."""

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

import clwave
from clwave.raytrace.reference import classified_reference

pytestmark = pytest.mark.opencl


def _smooth(shape, seed=7):
    r = gaussian_filter(np.random.default_rng(seed).random(shape), 1.5)
    return (r - r.min()) / np.ptp(r)


@pytest.mark.parametrize("scale", [1e-20, 1e-30])
def test_a_scalar_of_tiny_values_is_shaded(scale):
    # astrophysical densities (1e-24 g/cm^3): the squared world gradients underflowed float32 to 0, every normal was
    # flat and the image lost its diffuse and specular light (0.34 off); normals do not depend on the data's scale
    data = (scale * _smooth((11, 13, 9))).astype(np.float32)
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data, spacing=(1.0, 0.5, 2.0)), levels=1)
    tf = clwave.TransferFunction([(0.0, 1, 1, 1, 0.0), (scale, 1, 0.5, 0, 0.3)])
    cam = clwave.Camera(30, 25, (8, 9))
    tracer = clwave.RayTracer(wv)
    image = tracer.render(cam, transfer_function=tf, tolerance=1e-3).image
    assert np.abs(image - classified_reference(wv, cam, tf, tracer=tracer)).max() <= 1e-3
    unit = clwave.WaveletVolume.from_volume(clwave.Volume(data / np.float32(scale), spacing=(1.0, 0.5, 2.0)), levels=1)
    same = clwave.raytrace(unit, cam, tolerance=1e-3,
                           transfer_function=clwave.TransferFunction([(0.0, 1, 1, 1, 0.0), (1.0, 1, 0.5, 0, 0.3)]))
    assert np.abs(image - same.image).max() <= 1e-4 and image[..., 3].max() > 0.5


def test_a_detail_beyond_the_levels_is_named_as_given():
    # detail=2 on a one-level model was refused as "detail=Detail(level=2, pixels=None) must be ...": not what was given
    vol = clwave.Volume(_smooth((9, 7, 8)).astype(np.float32))
    tracer = clwave.RayTracer(clwave.WaveletVolume.from_volume(vol, levels=1), lod=True)
    with pytest.raises(clwave.InputError, match=r"^detail=2 must be a level from 0 \(full detail\) to 1 "):
        tracer.render(clwave.Camera(20, 30, (4, 4)), detail=2, absorption=False)
    with pytest.raises(clwave.InputError, match=r"^detail=Detail\(level=-1, pixels=None\) must be a level"):
        tracer.render(clwave.Camera(20, 30, (4, 4)), detail=clwave.Detail(-1), absorption=False)
