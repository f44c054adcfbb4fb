"""The ray tracer in a cone beam's own geometry (clwave.ConeBeam: principal point, rectangular pixels, roll): its X-ray
mode against exact perspective line integrals of the same spline (clwave/splat/reference.py's NumPy oracle), against
perspective splatting within issue #33's bound, and its progressive frames on reduced detectors."""

import numpy as np

import clwave
from clwave.splat.reference import exact_xray

BOUND = 1e-2  # splatting against the ray tracer, of the image maximum (issue #33)
TOL = 1e-4


def _model(shape, spacing, levels=1, seed=0):
    vol = clwave.Volume(np.random.default_rng(seed).random(shape).astype(np.float32), spacing=spacing)
    return clwave.WaveletVolume.from_volume(vol, wavelet="cubic", levels=levels)


def test_the_ray_tracer_traces_a_cone_beam_exactly():
    wv = _model((12, 14, 16), (1.5, 0.75, 1.0))
    cb = clwave.ConeBeam(60.0, 90.0, (22, 26), pixel=(1.7, 1.4), offset=(6.0, -4.0), azimuth=120, elevation=35,
                         roll=20, isocentre=(1.0, 0.5, -1.0))
    view = cb.view(wv)
    exact = exact_xray(wv.reconstruct().data, 4, wv.spacing, wv.origin, view)
    ray = clwave.raytrace(wv, cb, tolerance=TOL, absorption=False).image
    assert np.abs(ray - exact).max() <= TOL  # the tracer's contract: an absolute error per value
    assert np.count_nonzero(exact[..., 0] > 1e-3 * exact.max()) > 0.5 * exact[..., 0].size  # the content fills it
    # the offset moves the image: the same geometry without it is another image
    centred = clwave.ConeBeam(60.0, 90.0, (22, 26), pixel=(1.7, 1.4), azimuth=120, elevation=35, roll=20,
                              isocentre=(1.0, 0.5, -1.0))
    assert np.abs(clwave.raytrace(wv, centred, tolerance=TOL, absorption=False).image - ray).max() > 0.1 * ray.max()
    splat = clwave.splat(wv, cb).image
    assert np.abs(splat - ray).max() <= BOUND * ray.max()


def test_a_reduced_cone_beam_is_the_same_view_with_larger_pixels():
    wv = _model((8, 8, 8), (1.0, 1.0, 1.0))
    cb = clwave.ConeBeam(50.0, 80.0, (40, 36), pixel=(1.1, 0.9), offset=(3.0, 2.0), azimuth=30, elevation=-20, roll=10)
    small = cb.reduced(4)
    assert small.size == (10, 9) and small.pixel == (4.4, 3.6)
    points = np.random.default_rng(1).uniform(-4, 4, (20, 3))
    np.testing.assert_allclose(small.view(wv).to_pixels(points), (cb.view(wv).to_pixels(points) + 0.5) / 4 - 0.5,
                               rtol=0, atol=1e-9)


def test_progressive_cone_beam_frames_end_at_the_direct_render():
    wv = _model((10, 10, 10), (1.0, 1.0, 1.0), levels=1, seed=2)
    cb = clwave.ConeBeam(60.0, 90.0, (64, 64), pixel=0.6, offset=(2.0, -1.0), azimuth=40, elevation=15)
    tracer = clwave.RayTracer(wv, lod=True)
    frames = list(clwave.progressive(wv, cb, method="raytrace", tracer=tracer, tolerance=1e-3, absorption=False))
    assert len(frames) >= 2 and all(f.image.shape == (64, 64, 1) for f in frames)
    assert frames[0].figures()["reduction"] > 1  # a reduced detector first
    direct = tracer.render(cb, tolerance=1e-3, absorption=False).image
    assert np.array_equal(frames[-1].image, direct)
    assert frames[0].figures()["estimated_relative_rms_error"] > 0
