"""Post-classification of thin signed lobes under a sharp transfer function (trial30): the kernel against a dense
NumPy oracle, and what the nearly empty image's warning says (docs/raytracing.md §10, docs/model.md §5)."""

import re
import warnings

import numpy as np
import pytest
from scipy.ndimage import map_coordinates

import clwave
from clwave.raytrace.classified import opaque_where

#: trial30's tf_strong: blue below -0.9, red above 0.9, transparent within -0.85 .. 0.85
STRONG = [(-3, 0, 0, 1, .8), (-.9, 0, 0, 1, .8), (-.85, 1, 1, 1, 0), (.85, 1, 1, 1, 0), (.9, 1, 0, 0, .8),
          (3, 1, 0, 0, .8)]


def sheets(n=32, amplitudes=(1.1, -1.08, 1.0)):
    """Three dipping signed sheets, a 30 Hz Ricker sampled at 4 ms (2.65 samples), 9 samples apart: each sheet's
    voxels reach past 0.9, and the cubic model of them (the samples as its coefficients) crosses 0.9 over a voxel or
    two, or not at all."""
    z, y, x = np.mgrid[:n, :n, :n].astype(float)
    tau = z - (5 + 0.15 * x + 0.1 * y)
    u = ((tau[None] - 9 * np.arange(3)[:, None, None, None]) / 2.65) ** 2
    return np.einsum("k,kzyx->zyx", amplitudes, (1 - 2 * u) * np.exp(-u)).astype(np.float32)


def oracle(data, camera, tf, step):
    """(H, W, 4) unshaded emission-absorption of the cubic B-spline whose coefficients are ``data`` (scipy's
    ``map_coordinates`` without prefilter; zeros beyond), through ``tf`` (``np.interp``, the field clamped to the
    data's range) by the midpoint rule at ``step`` voxels over the box of the voxel centres (unit spacing, origin
    0); orthographic."""
    padded = np.pad(data.astype(np.float64), 3)
    view = camera.view(clwave.Volume(data))
    centres = view.pixel_centres().reshape(-1, 3) + (np.array(data.shape[::-1]) - 1) / 2  # (x, y, z) indices
    points = np.asarray(tf.points)
    d, out = -view.n, np.zeros((len(centres), 4))
    for i, p in enumerate(centres):
        with np.errstate(divide="ignore"):
            ta, tb = -p / d, (np.array(data.shape[::-1]) - 1 - p) / d
        t0, t1 = np.max(np.minimum(ta, tb)), np.min(np.maximum(ta, tb))
        if not t1 > t0:
            continue
        m = int(np.ceil((t1 - t0) / step))
        h = (t1 - t0) / m
        x = p + (t0 + (np.arange(m) + 0.5) * h)[:, None] * d
        s = np.clip(map_coordinates(padded, x[:, ::-1].T + 3, order=3, prefilter=False), data.min(), data.max())
        sigma = np.interp(s, points[:, 0], points[:, 4])
        depth = (np.cumsum(sigma) - sigma / 2) * h
        rgb = np.stack([np.interp(s, points[:, 0], points[:, c]) for c in (1, 2, 3)], axis=1)
        out[i] = *(rgb * (sigma * np.exp(-depth))[:, None]).sum(axis=0) * h, 1 - np.exp(-sigma.sum() * h)
    return out.reshape(*view.size, 4)


def test_thin_signed_lobes_against_a_dense_oracle():
    """The lobes above the sharp step cross |s| = 0.9 over at most two voxels along a ray's z: each value of the
    unshaded render within the tolerance of the oracle (whose own error, from a step of 1/64 to 1/128 of a voxel, is
    below 1e-4), at 1e-2 and 1e-3; the sheets show in a sixth of the pixels.  The third sheet's voxels reach past 0.9
    and its model does not (0.87 at the middle column): what post-classification classifies is the model, which
    smooths the voxels (docs/model.md §5)."""
    data = sheets()
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), levels=2)
    tf, cam = clwave.TransferFunction(STRONG), clwave.Camera(30, 20, size=24)
    fine, finer = oracle(data, cam, tf, 1 / 64), oracle(data, cam, tf, 1 / 128)
    assert np.abs(fine - finer).max() < 1e-4  # measured 7e-5
    assert 0.1 < np.mean(finer[..., 3] > 0.05) < 0.3 and finer[..., 3].max() > 0.9  # measured 0.175, 0.987
    tracer = clwave.RayTracer(wv)
    for tol in (1e-2, 1e-3):
        image = tracer.render(cam, tolerance=tol, transfer_function=tf, shading=False).image
        assert np.abs(image - finer).max() <= tol, (tol, np.abs(image - finer).max())  # measured 1.2e-4
    column = wv.evaluate(np.column_stack([np.zeros(400), np.zeros(400), np.linspace(-15.5, 15.5, 400)]), "bands")
    third = column[np.linspace(-15.5, 15.5, 400) > 8, 0]  # the third sheet, about z = 11.4
    assert np.abs(data[:, 16, 16][data.shape[0] * 2 // 3:]).max() > 0.95 and 0.8 < third.max() < 0.9


def test_where_a_function_is_opaque_is_said_as_it_is():
    """Signed, several intervals, ramps' feet, the ends held beyond the points."""
    values = np.array([-3, -.9, -.85, .85, .9, 3])
    assert opaque_where(values, np.array([.8, .8, 0, 0, .8, .8])) == "below -0.85 and above 0.85"
    assert opaque_where(np.array([-3, -1.6, -1.5, 3]), np.array([1, 1, 0, 0])) == "below -1.5"
    assert opaque_where(np.arange(6.0), np.array([0, 1, 0, 0, .5, 0])) == "from 0 to 2 and from 3 to 5"
    assert opaque_where(np.arange(8.0), np.array([0, 1, 0, 0, .5, 0, 0, 1])) == \
        "from 0 to 2, from 3 to 5 and above 6"
    assert opaque_where(np.arange(6.0), np.array([0, 1, 0, .2, 0, 0])) == "from 0 to 4"
    assert opaque_where(np.arange(2.0), np.array([1, 1])) == "everywhere"


def faint_warning(wv, tf, cam):
    with pytest.warns(clwave.ClwaveWarning, match="nearly empty") as told:
        clwave.RayTracer(wv).render(cam, tolerance=1e-2, transfer_function=tf)
    return next(str(w.message) for w in told if "nearly empty" in str(w.message))


def test_a_function_within_the_models_values_is_not_told_a_window():
    """trial30's strong reflectors in a small view: the function is opaque below -0.85 and above 0.85, within the
    model's values, so the nearly empty image's warning says so, names no window, and tells how the cubic model
    lowers thin peaks (--interpolate); an interpolating model is not told that, a window of values the model barely
    reaches still is."""
    data = np.zeros((32, 32, 32), np.float32)
    data[15:17, 15:17, 15:17] = sheets()[11:13, 15:17, 15:17]  # a speck of the first sheet's lobe, -1.1 .. 1.1
    data[0, 0, 0], data[-1, -1, -1] = -1.2, 1.2
    tf, cam = clwave.TransferFunction(STRONG, name="strong"), clwave.Camera(30, 20, size=32)
    line = faint_warning(clwave.WaveletVolume.from_volume(clwave.Volume(data), levels=2), tf, cam)
    assert re.search(r"strong is opaque below -0.85 and above 0.85, and this model's values lie within -1.\d+ \.\. "
                     r"1.\d+: its opacity lies within them.*smooths its voxels.*interpolate=True.*"
                     r"opacity_unit \(now 1\)", line) and "window" not in line
    line = faint_warning(clwave.WaveletVolume.from_volume(clwave.Volume(data), levels=2, interpolate=True), tf, cam)
    assert "its opacity lies within them" in line and "smooths" not in line and "window" not in line
    grey = clwave.TransferFunction.preset("grey", window=(1.15, 10))  # opacity at values the model barely reaches
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        line = faint_warning(clwave.WaveletVolume.from_volume(clwave.Volume(data), levels=2), grey, cam)
    assert "grey is opaque above 1.15" in line and "put its opacity there (a preset: window=(-1." in line
