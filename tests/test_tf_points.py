"""Transfer functions of thousands of points (a label map's categorical function, docs/raytracing.md §10): the
kernels search the table (cl/raytrace/tf_table.h) in log K, and classify as they do a function of a few points."""

import warnings

import numpy as np
import pyopencl.array as cla
import pytest
from numpy.polynomial import Polynomial
from pyopencl import cltypes

import clwave
from clwave.device import programs
from clwave.device.context import ComputeContext
from clwave.errors import ClwaveWarning
from clwave.raytrace.classified import _BOUNDS, post_nodes, tf_table
from clwave.raytrace.quadrature import sample_points, sample_tables
from test_classify import CHECK, exact_segment

LABELS = 2000


def many_labels(seed, count=LABELS):
    """``count`` labels of random colour and opacity, every other whole number from 1 (4 points a label)"""
    rng = np.random.default_rng(seed)
    return clwave.TransferFunction.labels({2 * i + 1: (*rng.uniform(0, 1, 3), rng.uniform(0.05, 2.0))
                                           for i in range(count)})


def test_the_bounds_are_the_largest_opacity_over_each_range():
    """classified_bounds (tf_peak's max tree) against the largest of np.interp at a range's ends and at the points
    inside it, for ranges of one point up to all of them, each end on a point, between points or beyond them."""
    tf = many_labels(1)
    values, alpha = tf.points[:, 0], tf.points[:, 4]
    assert len(values) == 4 * LABELS
    rng = np.random.default_rng(2)
    ends = np.concatenate([rng.choice(values, 3000), rng.uniform(-10, 2 * LABELS + 10, 3000)]).astype(np.float32)
    width = np.concatenate([np.zeros(500), rng.exponential(4.0, 4000), rng.uniform(0, 2 * LABELS, 1500)])
    ranges = np.column_stack([ends, ends + rng.permutation(width)]).astype(np.float32)
    cc = ComputeContext.get()
    q, table = cc.queue, tf_table(tf, None, (1.0, 1.0, 1.0)).astype(np.float32)
    bound = cla.empty(q, len(ranges), np.float32)
    _BOUNDS(programs.build(cc, ["raytrace/scalar.cl"]), q, (len(ranges),), None, bound=bound,
            range=cla.to_device(q, ranges), tf=cla.to_device(q, table), slack=0.0, n=len(ranges))
    scale, shift = table[0, :2]
    u = ranges * scale + shift  # in float32, as the kernel maps them
    K = len(values)
    points = table[1:K + 1, 0]
    line = table[1 + K + 3 * np.searchsorted(points, u, "right")].astype(np.float64)  # the ends' intervals' lines
    want = np.maximum(line[..., 1] + line[..., 2] * (u - line[..., 0]), 0).max(axis=1)
    first, end = np.searchsorted(points, u[:, 0], "left"), np.searchsorted(points, u[:, 1], "right")
    for i in np.flatnonzero(end > first):
        want[i] = max(want[i], alpha[first[i]:end[i]].max())
    np.testing.assert_allclose(bound.get(), want, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("shading", [False, True])
def test_segments_through_thousands_of_labels_against_fine_quadrature(shading):
    """A post-classified segment through the categorical function of 2,000 labels (8,000 points) on cubics crossing
    a few of its steps anywhere along it, and quadratics crossing 100 to 240 (each cut, none left unresolved), shaded
    or not: the optical depth exact and the emission within the tolerance of test_classify's exact_segment (scipy's
    quad cut at every root), as for a function of a few points."""
    cc = ComputeContext.get()
    if not cc.queue.device.double_fp_config:
        pytest.skip("no float64 on this device")
    rng = np.random.default_rng(11)
    tf = many_labels(3)
    nodes, weights = sample_tables(9)
    xi = sample_points(9)
    nodes = post_nodes(nodes, len(xi))
    kernels = programs.build(cc, ["raytrace/classify_check.cl"], dict(
        CLW_POST=None, CLW_SAMPLES=len(xi), CLW_GROUPS=1, CLW_ORDERS=4, CLW_MAX_DEPTH=16, CLW_DOUBLE=None,
        **({"CLW_SHADE": None} if shading else {})))
    tol, q = 1e-6, cc.queue
    table = tf_table(tf, None, (1.0, 1.0, 1.0))
    polys = [Polynomial([rng.uniform(0, 2 * LABELS + 2), rng.uniform(-2.0, 2.0), rng.normal(0, 0.3),
                         rng.normal(0, 0.1)]) for _ in range(24)]
    polys += [Polynomial([rng.uniform(100, 2 * LABELS - 100), slope, rng.normal(0, 1.0)]) for slope in (-40, 25, 60)]
    grads = [[Polynomial(rng.normal(0, 1, 9) * 0.5 ** np.arange(9)) for _ in range(3)] for _ in polys]
    light = np.array([0.6, 0.0, 0.8])
    halfway = (light + [0.0, 0.0, 1.0]) / np.linalg.norm(light + [0.0, 0.0, 1.0])
    radius = rng.uniform(0.2, 3.0, len(polys))
    samples = np.array([p(xi) for p in polys])
    lanes = np.zeros((len(polys), 3, 16))
    lanes[:, :, :9] = [[g(xi[:9]) for g in gr] for gr in grads]
    out = cla.empty(q, len(polys), cltypes.double4)
    stats = cla.empty(q, len(polys), cltypes.int4)
    CHECK(kernels, q, (len(polys),), None, real_type=np.float64, out=out, samples=cla.to_device(q, samples),
          grads=cla.to_device(q, lanes), radius=cla.to_device(q, radius), nodes=cla.to_device(q, nodes),
          weights=cla.to_device(q, weights), tf=cla.to_device(q, table), tol=tol,
          shading=cla.to_device(q, np.array([0.3, 0.7, 0.3, 20.0, *light, *halfway, 1e-12])),
          budget=cla.to_device(q, np.zeros(len(polys))), stats=stats, n=len(polys))
    got, stat = out.get(), stats.get()
    crossed = 0
    for p, g, r, v, st in zip(polys, grads, radius, got, stat):
        s = p(np.linspace(-1, 1, 2001))  # the oracle takes the points about the segment's values (quad's cost)
        near = slice(max(np.searchsorted(tf.points[:, 0], s.min() - 0.1) - 1, 0),
                     np.searchsorted(tf.points[:, 0], s.max() + 0.1) + 1)
        emission, depth = exact_segment(p, clwave.TransferFunction(tf.points[near]), r,
                                        *((g, light, halfway) if shading else ()))
        assert st["x"] == 0  # every span resolved
        assert abs(v["w"] - depth) <= 1e-9 * max(1.0, depth)
        assert np.max(np.abs([v["x"] - emission[0], v["y"] - emission[1], v["z"] - emission[2]])) <= tol
        crossed += not st["z"]
    assert 10 < crossed < len(polys)  # most segments cut at steps, some inside one interval


def test_a_label_map_of_thousands_of_labels_shows_each_ray_its_labels():
    """A Haar model of 2,000 labels (every other one shown) seen down z: a pixel's ray crosses one column of voxels,
    whose labels are its values, so its RGBA is the front-to-back composite of the column's cells (a closed form)."""
    rng = np.random.default_rng(5)
    labels = rng.integers(0, 2 * LABELS + 1, (6, 16, 16))
    tf = many_labels(7)
    vol = clwave.Volume(labels.astype(np.float32), spacing=(1.0, 1.0, 1.0))
    cam = clwave.Camera(azimuth=0, elevation=90, size=64, target=(0, 0, 0), extent=17.0)
    view = cam.view(vol)
    index = vol.world_to_voxel(view.pixel_centres().reshape(-1, 3))
    inside = np.all((index[:, 1:] > -0.5) & (index[:, 1:] < 15.5), axis=1)
    sure = inside & np.all(np.abs(index[:, 1:] - np.rint(index[:, 1:])) < 0.45, axis=1)  # not on a cell's edge
    j, k = np.rint(index[:, 1:]).astype(int).clip(0, 15).T
    rgb, alpha = tf(labels[:, j, k].T.ravel())  # each pixel's column, cell by cell
    met = slice(None) if -view.n[2] > 0 else slice(None, None, -1)  # the slices in the order the rays meet them
    rgb, alpha = rgb.reshape(len(j), 6, 3)[:, met], alpha.reshape(len(j), 6)[:, met]
    kept = np.exp(-alpha)  # each unit cell's transmittance
    front = np.concatenate([np.ones((len(j), 1)), np.cumprod(kept, axis=1)[:, :-1]], axis=1)
    want = np.column_stack([(rgb * ((1 - kept) * front)[:, :, None]).sum(axis=1), 1 - kept.prod(axis=1)])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ClwaveWarning)  # Haar's no shading
        wv = clwave.WaveletVolume.from_volume(vol, wavelet="haar", levels=1).threshold(keep=1.0)
        image = clwave.raytrace(wv, cam, transfer_function=tf, tolerance=1e-4).image.reshape(-1, 4)
    assert sure.sum() > 2000 and (want[sure, 3] > 0.5).sum() > 1000
    np.testing.assert_allclose(image[sure], want[sure], atol=1e-3)
