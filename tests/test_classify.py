"""Post-classification (docs/raytracing.md §10): a scalar model ray traced through a transfer function given at
render time, held to independent answers."""

import re
import warnings

import numpy as np
import pyopencl.array as cla
from pyopencl import cltypes
import pytest
from numpy.polynomial import Polynomial
from scipy.integrate import quad

import clwave
from clwave.model.wavelet import WaveletVolume
from clwave.device import programs
from clwave.device.context import ComputeContext
from clwave.device.kernels import BUFFER, REAL, Kernel
from clwave.errors import InputError
from clwave.raytrace.classified import post_nodes, tf_table
from clwave.raytrace.quadrature import sample_points, sample_tables
from clwave.raytrace.reference import _content_field, classified_reference

CHECK = Kernel("classify_segments", ("out", BUFFER), ("samples", BUFFER), ("grads", BUFFER), ("radius", BUFFER),
               ("nodes", BUFFER), ("weights", BUFFER), ("tf", BUFFER), ("tol", REAL), ("shading", BUFFER),
               ("budget", BUFFER), ("stats", BUFFER), ("n", np.int32))
UNPACK = Kernel("unpack_pool", ("out", BUFFER), ("words", BUFFER), ("quant", BUFFER), ("boxes", BUFFER))
CELLS = Kernel("unpack_cells", ("out", BUFFER), ("words", BUFFER), ("quant", BUFFER), ("boxes", BUFFER),
               ("cells", BUFFER), ("j", np.int32))
PHONG = (0.3, 0.7, 0.3, 20.0)  # ka, kd, ks, shininess (clwave.Phong's defaults)


def random_tf(rng, lo, hi, steps=True, clear=False):
    """A random piecewise-linear transfer function over (lo, hi); with ``steps``, a jump over 1e-4 of the range;
    ``clear``: transparent from lo up to its second point."""
    k = rng.integers(3, 7)
    values = np.sort(rng.uniform(lo, hi, k))
    if clear:
        values[0] = lo
    if steps:
        at = rng.integers(0, k)
        values = np.sort(np.append(values, values[at] + 1e-4 * (hi - lo)))
    rows = np.column_stack([values, rng.uniform(0, 1, (len(values), 3)), rng.uniform(0, 2, len(values))])
    rows[rng.random(len(values)) < 0.3, 4] = 0.0  # transparent stretches
    if clear:
        rows[:2, 4] = 0.0
    return clwave.TransferFunction(rows)


def one_sign(poly, tf):
    """The sign of the opacity's slope in the transfer function's interval holding poly(0) (+1 where flat): the
    normals face where the opacity decreases."""
    values, alpha = tf.points[:, 0], tf.points[:, 4]
    k = np.searchsorted(values, poly(0.0), side="right")
    return -1.0 if 0 < k < len(values) and alpha[k] < alpha[k - 1] else 1.0


def exact_segment(poly, tf, radius, grad=None, light=None, halfway=None):
    """(int q' e^{-radius A} dxi, int alpha dxi) over [-1, 1] for the scalar ``poly`` (a Polynomial in xi), cut at
    every real root of poly - v (NumPy's roots); alpha is a polynomial on each piece, integrated exactly, and the
    emission comes from scipy's quad with tight tolerances.  With ``grad`` (three Polynomials: the gradient of s),
    q' is Phong-shaded (PHONG) by one light: n = -grad/|grad|, turned where the opacity falls with s, and the pieces
    are cut again at the real roots of grad . light and grad . halfway, where the shading kinks."""
    values, alpha_pts, colour = tf.points[:, 0], tf.points[:, 4], tf.points[:, 1:4]
    cuts = {-1.0, 1.0}
    lines = [poly - v for v in values]
    if grad is not None:
        lines += [sum(g * d for g, d in zip(grad, direction)) for direction in (light, halfway)]
    for line in lines:
        cuts |= {r.real for r in line.roots() if abs(r.imag) < 1e-9 and -1 < r.real < 1}
    cuts = sorted(cuts)
    ka, kd, ks, shininess = PHONG

    def shaded(xi, s, alpha, q):
        if grad is None:
            return q
        k = np.searchsorted(values, s, side="right")  # the interval: the normal faces where alpha decreases
        slope = 0.0 if k in (0, len(values)) else alpha_pts[k] - alpha_pts[k - 1]
        g = np.array([p(xi) for p in grad]) * (-1.0 if slope < 0 else 1.0)
        n = -g / np.linalg.norm(g)
        c = n @ halfway
        return q * (ka + kd * max(n @ light, 0.0)) + ks * alpha * (c ** shininess if c > 0 else 0.0)

    emission, depth = np.zeros(3), 0.0
    for a, b in zip(cuts[:-1], cuts[1:]):
        if b - a < 1e-12:  # coincident roots (a light and its halfway vector): nothing between them
            continue
        x = np.linspace(a, b, 12)  # alpha(poly) on the piece: a polynomial of poly's degree
        alpha = Polynomial.fit(x, np.interp(poly(x), values, alpha_pts), poly.degree())  # on its own domain [a, b]
        integral = alpha.integ(lbnd=a)
        for c in range(3):
            def f(xi, c=c, integral=integral, d=depth):
                s = poly(xi)
                opacity = np.interp(s, values, alpha_pts)
                return shaded(xi, s, opacity, np.interp(s, values, colour[:, c]) * opacity) \
                    * np.exp(-radius * (d + integral(xi)))
            emission[c] += quad(f, a, b, epsabs=1e-13, epsrel=1e-12, limit=200)[0]
        depth += integral(b)
    return emission, depth


@pytest.mark.parametrize("precision", ["double", "single"])
@pytest.mark.parametrize("shading", [False, True])
def test_segment_integral_against_fine_quadrature(precision, shading):
    """A post-classified segment (post_segment, post_gradient) on random cubics (and degree-9 polynomials) through
    random piecewise-linear transfer functions with steps, shaded by a random light with random degree-8 gradients or
    unshaded: the optical depth exact, the emission within the tolerance plus what the segment took from the shading
    budget.  Every path runs: cut segments, whole ones inside one interval by Simpson on their samples (a budget of
    0), and (shaded, a budget of 10) at the midpoint, whose error stays within the cost it charged, and, lit by a
    headlight, those turned away from it (s falling along the ray where the opacity rises with s) with no gradient
    at a small cost.  The gradients' component along the view direction is ds/dt, as in a render."""
    cc = ComputeContext.get()
    if precision == "double" and not cc.queue.device.double_fp_config:
        pytest.skip("no float64 on this device")
    real = np.float64 if precision == "double" else np.float32
    real4 = {np.float64: cltypes.double4, np.float32: cltypes.float4}[real]
    rng = np.random.default_rng(7)
    nodes, weights = sample_tables(9)
    xi = sample_points(9)
    nodes = post_nodes(nodes, len(xi))
    kernels = programs.build(cc, ["raytrace/classify_check.cl"], dict(
        CLW_POST=None, CLW_SAMPLES=len(xi), CLW_GROUPS=1, CLW_ORDERS=4, CLW_MAX_DEPTH=16,
        **({"CLW_DOUBLE": None} if precision == "double" else {}), **({"CLW_SHADE": None} if shading else {})))
    tol = 1e-6 if precision == "double" else 1e-3
    q = cc.queue
    worst, paths, unlit = 0.0, np.zeros(3, int), 0  # cut, one interval, midpoint; turned from a headlight
    fine = np.linspace(-1, 1, 201)
    for trial in range(6):
        tf = random_tf(rng, -1.0, 1.0, steps=trial % 2 == 0)
        table = tf_table(tf, None, (1.0, 1.0, 1.0))
        polys = [Polynomial(rng.normal(0, 0.6, 4 if i % 2 else 10) * 0.5 ** np.arange(4 if i % 2 else 10))
                 for i in range(10)]
        # and three gentle ones, nearly linear around a random value, rising or falling: mostly inside one interval
        polys += [Polynomial(np.r_[rng.uniform(-1, 1), rng.choice([-1, 1]) * rng.uniform(5e-3, 3e-2),
                                   rng.normal(0, 5e-4, 2)]) for _ in range(3)]
        grads = [[Polynomial(rng.normal(0, 1, 9) * 0.5 ** np.arange(9)) for _ in range(3)] for _ in polys]
        light = rng.normal(size=3)
        light /= np.linalg.norm(light)
        halfway = light if trial % 3 == 0 else light + rng.normal(size=3) * 0.5
        halfway = halfway / np.linalg.norm(halfway)
        radius = rng.uniform(0.2, 3.0, len(polys))
        # the gradient of s along the view direction w (given by L and H: w = L - 2 (L.H) H) is ds/dt, as in the ray
        # tracer (interval_unlit relies on it): the random gradients' component along w replaced by s' / radius
        w = light - 2 * (light @ halfway) * halfway
        grads = [[gr[a] - w[a] * sum(w[b] * gr[b] for b in range(3)) + w[a] * p.deriv() / r for a in range(3)]
                 for p, gr, r in zip(polys, grads, radius)]
        samples = np.array([p(xi) for p in polys])
        lanes = np.zeros((len(polys), 3, 16))
        lanes[:, :, :9] = [[g(xi[:9]) for g in gr] for gr in grads]
        for budget in ((0.0, 10.0) if shading else (0.0,)):
            out = cla.empty(q, len(polys), real4)
            left = cla.to_device(q, np.full(len(polys), budget, real))
            stats = cla.empty(q, len(polys), cltypes.int4)
            CHECK(kernels, q, (len(polys),), None, real_type=real, out=out,
                  samples=cla.to_device(q, samples.astype(real)), grads=cla.to_device(q, lanes.astype(real)),
                  radius=cla.to_device(q, radius.astype(real)), nodes=cla.to_device(q, nodes.astype(real)),
                  weights=cla.to_device(q, weights.astype(real)), tf=cla.to_device(q, table.astype(real)), tol=tol,
                  shading=cla.to_device(q, np.array([*PHONG, *light, *halfway, 1e-12], real)), budget=left,
                  stats=stats, n=len(polys))
            got, charged, stat = out.get(), budget - left.get(), stats.get()
            for p, g, r, v, cost, st in zip(polys, grads, radius, got, charged, stat):
                emission, depth = exact_segment(p, tf, r, *((g, light, halfway) if shading else ()))
                assert abs(v["w"] - depth) <= (1e-9 if precision == "double" else 1e-5) * max(1.0, depth)
                error = np.max(np.abs([v["x"] - emission[0], v["y"] - emission[1], v["z"] - emission[2]]))
                worst = max(worst, error)
                assert error <= tol + cost, (trial, budget, error, cost, st)  # cost: what the midpoint charged
                paths += [not st["z"], st["z"] and not st["y"], st["y"]]
                # turned away from a headlight inside one interval: no gradient, and charged little (interval_unlit)
                if shading and budget and trial % 3 == 0 and st["z"] and one_sign(p, tf) * p.deriv()(fine).max() < 0:
                    unlit += 1
                    assert st["y"] and cost <= 0.1 * np.max(emission) + 1e-9, (trial, cost, emission)
    assert worst > 0 and paths[0] > 0 and paths[1] > 0 and (paths[2] > 0) == shading, paths
    assert (unlit > 0) == shading, unlit


def test_table_against_the_transfer_function():
    """The kernel's table evaluates to TransferFunction.__call__ (an independent np.interp-style evaluation) at
    random values, windowed, its opacity per voxel divided by the model's smallest spacing (extinction per world
    unit, docs/model.md §5)."""
    rng = np.random.default_rng(3)
    tf = clwave.TransferFunction.preset("ct-bone", window=(-500.0, 1500.0))
    table = tf_table(tf, tf.window, (0.5, 0.25, 2.0))
    scale, shift, K = table[0, :3]
    K = int(K)
    s = rng.uniform(-800, 1800, 500)
    u = s * scale + shift
    k = np.sum(table[1:K + 1, 0][None, :] <= u[:, None], axis=1)
    line, rgb, slope = table[1 + K + 3 * k], table[2 + K + 3 * k], table[3 + K + 3 * k]
    alpha = line[:, 1] + line[:, 2] * (u - line[:, 0])
    colour = rgb[:, :3] + slope[:, :3] * (u - line[:, 0])[:, None]
    want_rgb, want_alpha = tf(s)
    np.testing.assert_allclose(alpha, want_alpha / 0.25, atol=1e-12)
    np.testing.assert_allclose(colour, want_rgb, atol=1e-12)


@pytest.fixture(scope="module")
def hydrogen():
    vol = clwave.phantom("hydrogen", n=20)
    wv = clwave.WaveletVolume.from_volume(vol, wavelet="cubic", levels=2).threshold(keep=0.1)
    return wv, clwave.RayTracer(wv)


@pytest.mark.parametrize("shading", [False, True])
def test_image_against_float64_oracle(hydrogen, shading):
    """Hydrogen with its preset, shaded and unshaded: each value within the tolerance of the brute-force float64
    oracle (which has no skipping, no termination and no adaptivity), at 1e-2 and 1e-3."""
    wv, tr = hydrogen
    tf = clwave.TransferFunction.preset("hydrogen")
    cam = clwave.Camera(30, 20, size=12)
    ref = classified_reference(wv, cam, tf, shading=shading, tracer=tr)
    assert ref[..., 3].max() > 0.1
    for tol in (1e-2, 1e-3):
        img = tr.render(cam, tolerance=tol, transfer_function=tf, shading=shading).image
        assert np.abs(img - ref).max() <= tol


def ct_phantom(n=20):
    """A CT-like phantom in Hounsfield units: air (-1000) around soft tissue (40) holding a bone shell (1200)."""
    z, y, x = np.mgrid[:n, :n, :n] - (n - 1) / 2
    r = np.sqrt(x ** 2 + (1.3 * y) ** 2 + z ** 2) / (n / 2)
    hu = np.where(r < 0.85, 40.0, -1000.0)
    hu = np.where((r > 0.45) & (r < 0.6), 1200.0, hu)
    return clwave.Volume(hu.astype(np.float32), spacing=(1.0, 1.0, 1.0))


def test_sharp_bone_threshold_does_not_alias():
    """ct-bone with a threshold over 2 HU, on a CT-like phantom (perspective, shaded): within the tolerance of the
    oracle, so a sharp transfer function is integrated, not sampled."""
    vol = ct_phantom()
    wv = clwave.WaveletVolume.from_volume(vol, wavelet="cubic", levels=2).threshold(keep=0.2)
    tr = clwave.RayTracer(wv)
    sharp = clwave.TransferFunction([(-1000, 0.9, 0.8, 0.7, 0), (300, 0.9, 0.8, 0.7, 0), (302, 1, 1, 1, 0.4),
                                     (2000, 1, 1, 1, 0.4)])
    cam = clwave.Camera(20, 30, size=12, perspective=True, fov=40)
    ref = classified_reference(wv, cam, sharp, tracer=tr)
    assert ref[..., 3].max() > 0.5
    for tol in (1e-2, 1e-3):
        img = tr.render(cam, tolerance=tol, transfer_function=sharp).image
        assert np.abs(img - ref).max() <= tol


def crop_camera(model, azimuth, elevation, size, rows, cols):
    """The pixels ``rows`` x ``cols`` (slices) of a ``size``-square view, as a camera of their own."""
    full = clwave.Camera(azimuth, elevation, size=size).view(model)
    centres = full.pixel_centres()[rows, cols]
    return clwave.Camera(azimuth, elevation, size=centres.shape[:2], extent=full.pixel * centres.shape[1],
                         target=centres.reshape(-1, 3).mean(axis=0))


def mni152(step=6) -> clwave.Volume:
    """The MNI152 T1 MRI template inside the nilearn wheel, averaged over step^3 boxes."""
    from test_progressive_raytrace import NILEARN_T1, nilearn_file

    vol = clwave.load(nilearn_file(NILEARN_T1))
    n = [s // step for s in vol.shape]
    boxes = vol.data[:n[0] * step, :n[1] * step, :n[2] * step].reshape(n[0], step, n[1], step, n[2], step)
    return clwave.Volume(boxes.mean(axis=(1, 3, 5)), spacing=tuple(step * np.asarray(vol.spacing)))


def shepp_logan_hu(n) -> clwave.Volume:
    """A CT-like phantom: Shepp-Logan in Hounsfield units (outside -1000, the brain about 0..60, the skull 1200)."""
    v = clwave.phantom("shepp-logan", n=n).data
    return clwave.Volume(np.interp(v, [0.0, 0.1, 0.5, 1.0], [-1000.0, 0.0, 60.0, 1200.0]).astype(np.float32))


@pytest.mark.parametrize("case", ["ct-like", "marschner-lobb", "mni152"])
def test_volumes_against_float64_oracle(case):
    """Shaded, each value within the tolerance of the float64 oracle at 1e-2 and 1e-3: a CT-like phantom with
    ct-bone (64^3, the pixels where the skull's ridge flips the normal against the headlight: 1.03e-3 at tolerance
    1e-3 before the pieces were cut where grad s . L changes sign), Marschner-Lobb with grey, the MNI152 MRI
    (averaged over 6^3 boxes) with mri."""
    vol, preset, levels, keep, view = {
        "ct-like": (shepp_logan_hu(64), "ct-bone", 3, 0.05, (0, 0, 512, slice(267, 269), slice(275, 277))),
        "marschner-lobb": (clwave.phantom("marschner-lobb", n=32), "grey", 2, 0.1,
                           (30, 20, 64, slice(29, 31), slice(31, 33))),
        "mni152": (mni152(), "mri", 2, 0.1, (120, 10, 64, slice(31, 33), slice(25, 27)))}[case]
    wv = clwave.WaveletVolume.from_volume(vol, wavelet="cubic", levels=levels).threshold(keep=keep)
    tr = clwave.RayTracer(wv)
    tf = clwave.TransferFunction.preset(preset)
    cam = crop_camera(wv, *view)
    ref = classified_reference(wv, cam, tf, tracer=tr)
    assert ref[..., 3].min() > 0.05  # every pixel sees content
    for tol in (1e-2, 1e-3):
        img = tr.render(cam, tolerance=tol, transfer_function=tf).image
        assert np.abs(img - ref).max() <= tol, (tol, np.abs(img - ref).max())


def test_skipping_never_skips_content(hydrogen):
    """For random transfer functions, the block bounds are the largest opacity over the blocks' ranges (dense
    sampling), every block whose bound is 0 (skipped) holds no opacity: the model (its content-clamped B-spline
    form, evaluated in closed form) and the packed model the kernel renders (its bricks' decoded coefficients, brute
    force) at 20 random points per such block, classified, are 0 there; and the images match the oracle."""
    wv, tr = hydrogen
    rng = np.random.default_rng(11)
    cam = clwave.Camera(120, -10, size=8)
    from clwave.device.constants import BLOCK, SUPER
    from clwave.model.geometry import world_to_fine_affine
    scale, offset = world_to_fine_affine(tr.orders[0], wv.shape, wv.spacing, wv.origin)
    field = _content_field(wv)  # the model the B-spline field holds: zero beyond the content (§4)
    f, pages = tr.bricks, tr.field_at(0).pages
    decoded = decoded_pool(tr)[0]

    def quantized(fine):  # the packed model at fine points (P, 3) (z, y, x) of one brick
        slot = pages[tuple(int(k) for k in fine[0] // (SUPER * BLOCK) - f.origin)]
        return np.zeros(len(fine)) if slot < 0 else \
            brick_field(decoded, f.boxes[slot, 0], f.frames[slot, 0], tr.orders[0], fine[:, ::-1])
    for trial in range(3):
        tf = random_tf(rng, 0.0, 1.0, steps=trial != 1, clear=True)
        bound = tr.scalar.classify(tf, tr.cc, np.float32).bound.get()
        # the largest opacity over each block's range, sampled densely and at the points inside it
        ranges = tr.scalar.range(tr.field_at(0)).get().reshape(-1, 2)
        some = rng.choice(len(ranges), 300, replace=False)
        points = tf.points[:, 0]
        dense = np.array([tf(np.concatenate([np.linspace(a, b, 101), points[(points >= a) & (points <= b)]]))[1].max()
                          for a, b in ranges[some]])
        got = bound.ravel()[some]  # never below (skipping is safe); above by the ranges' float32 slack at most
        assert np.all(got >= dense - 1e-6) and np.all(got <= dense + 1e-3 * tf.points[:, 4].max())
        empty = np.argwhere(bound == 0)
        assert 0 < len(empty) < bound.size
        picks = empty[rng.choice(len(empty), min(200, len(empty)), replace=False)]
        fine = (tr.occ_origin + picks)[:, None, :] * BLOCK + rng.uniform(0, BLOCK, (len(picks), 20, 3))  # (z, y, x)
        world = (fine[..., ::-1].reshape(-1, 3) - offset) / scale
        _, alpha = tf(field(world, False)[:, 0])
        assert alpha.max() == 0
        assert max(tf(quantized(points))[1].max() for points in fine) == 0
        # the lookup finds the brick: the packed model is the model where there is content
        full = np.column_stack(np.unravel_index(np.argsort(bound, axis=None)[-5:], bound.shape))
        inside = (tr.occ_origin + full)[:, None, :] * BLOCK + rng.uniform(0, BLOCK, (len(full), 20, 3))
        exact = field((inside[..., ::-1].reshape(-1, 3) - offset) / scale, False)[:, 0].reshape(len(full), 20)
        within = tr.quant.get()["step"].max() / 2 + 1e-6 * np.abs(exact).max()  # half a step, and float32 bricks
        assert np.abs(exact).max() > 1e-2 and np.abs(np.array([quantized(p) for p in inside]) - exact).max() <= within
        img = tr.render(cam, tolerance=1e-3, transfer_function=tf).image
        assert np.abs(img - classified_reference(wv, cam, tf, tracer=tr)).max() <= 1e-3


def pool_kernels(cc):
    """The packed pool's harness kernels (``cl/raytrace/classify_check.cl``) for a cubic float32 field."""
    return programs.build(cc, ["raytrace/classify_check.cl"], dict(CLW_POST=None, CLW_SAMPLES=9, CLW_GROUPS=1,
                                                                   CLW_ORDERS=4, CLW_MAX_DEPTH=16))


def decoded_pool(tr):
    """(coefficients offset + step q float64, q, step per coefficient) of the tracer's packed scalar pool, q as the
    ray tracer reads them (``pool_row``, by the ``unpack_pool`` harness kernel); the slots one after another."""
    cc, f = tr.cc, tr.bricks
    kernels = pool_kernels(cc)
    boxes = np.ascontiguousarray(f.boxes[:, 0])
    sizes = np.prod(boxes[:, :3].astype(np.int64), axis=1)
    out = cla.zeros(cc.queue, int(sizes.sum()), np.float32)
    UNPACK(kernels, cc.queue, (len(boxes),), None, out=out, words=f.pool, quant=tr.quant,
           boxes=cla.to_device(cc.queue, boxes))
    quant = tr.quant.get()
    q = out.get().astype(np.float64)
    step = quant["step"].astype(np.float64).repeat(sizes)
    return quant["offset"].astype(np.float64).repeat(sizes) + step * q, q, step


def brick_field(coef, box, frame, order, fine):
    """Brute force: the field of one brick at grid-0 fine points (P, 3) (x, y, z), the sum over its lattice
    coefficients (box (nx, ny, nz, first)) of coef times the cardinal B-splines of ``order`` on [i, i + order] in
    the brick's lattice coordinates (fine - frame.xyz) * frame.w (cl/raytrace/field_bspline.h)."""
    from scipy.interpolate import BSpline

    n, first = box[:3], box[3]
    c = np.asarray(coef[first:first + np.prod(n)], np.float64).reshape(n[::-1])
    x = (fine - frame[:3]) * frame[3]
    basis = BSpline.basis_element(np.arange(order + 1), extrapolate=False)
    w = [np.nan_to_num(basis(x[:, a:a + 1] - np.arange(n[a]))) for a in range(3)]
    return np.einsum("zyx,pz,py,px->p", c, w[2], w[1], w[0])


def test_packed_pool_within_half_a_step(monkeypatch):
    """The scalar pool packed with 0..14 or 16 bits a tile of 4 x 4 x-rows (docs/raytracing.md §10): the ray tracer's
    decode, a row read from any x and every cubic cell as `scalar_cell` reads it (`pool_cell`, its rows in up to four
    tiles), gives the host's q exactly (the nearest whole number of the step S, one for a pool of full detail alone, the
    widest slot's range / 65535, above the slot's least coefficient), each tile has the fewest bits covering its q
    above its least, its coefficients within half a step; brute force at random points of random blocks: the brick's
    field from the float coefficients is the model's (the float64 closed form), the field from the decoded ones within
    half a step of it, both in the block's range that skipping classifies; the pool's words are the tiles' bits."""
    from clwave.device.constants import BLOCK, SUPER
    from clwave.model.geometry import world_to_fine_affine
    from clwave.raytrace import classified

    seen, pack = {}, classified.pack

    def spy(scalar, boxes, full, abandon):
        seen["float"], seen["boxes"] = scalar.copy(), np.array(boxes, np.int64)
        assert np.all(full)  # a tracer of full detail alone: one step for the pool
        return pack(scalar, boxes, full, abandon)

    monkeypatch.setattr(classified, "pack", spy)
    vol = clwave.phantom("hydrogen", n=20)
    wv = clwave.WaveletVolume.from_volume(vol, wavelet="cubic", levels=2).threshold(keep=0.1)
    tr = clwave.RayTracer(wv)
    f, order, boxes, quant = tr.bricks, tr.orders[0], seen["boxes"], tr.quant.get()
    sizes, starts = np.prod(boxes[:, :3], axis=1), boxes[:, 3]
    n = sizes.sum()  # the slots lie one after another from element 0
    coef = seen["float"][:n].astype(np.float64)
    decoded, q, steps = decoded_pool(tr)
    slot_of = np.repeat(np.arange(len(sizes)), sizes)
    lo = np.minimum.reduceat(coef, starts)
    bound = (np.maximum.reduceat(coef, starts) - lo).max() / 65535
    assert np.all(steps == steps[0]) and bound <= steps[0] <= bound * (1 + 1e-6)
    np.testing.assert_array_equal(q, np.rint((coef - lo[slot_of]) / steps))
    words, total, widths = f.pool.get(), 0, []
    for s, (nx, ny, nz, first) in enumerate(boxes):  # each tile's entry: the fewest bits above its least q
        c = q[first:first + sizes[s]].reshape(nz, ny, nx)
        tiles = [c[z:z + 4, y:y + 4] for z in range(0, nz, 4) for y in range(0, ny, 4)]
        entries = words[quant["word"][s]:quant["word"][s] + 2 * len(tiles)].reshape(-1, 2)
        base, bits = entries[:, 1] & 0xFFFF, (entries[:, 1] >> 16).astype(np.int64)
        np.testing.assert_array_equal(base, [t.min() for t in tiles])
        top = np.array([t.max() - t.min() for t in tiles])
        fewer = np.where(bits == 16, 14, bits - 1)  # the next width down (15 is not used: cl/raytrace/scalar_pool.h)
        assert np.all(top <= 2.0 ** bits - 1) and np.all(top[bits > 0] > 2.0 ** fewer[bits > 0] - 1)
        assert not np.any(bits == 15) and quant["tiles_y"][s] == -(-ny // 4)
        total += 2 * len(tiles) + np.sum(-(-np.array([t.size for t in tiles]) * bits // 32))
        widths.append(len(np.unique(bits)))
    assert max(widths) > 2  # tiles of a slot differ
    assert tr.bricks.pool_bytes == 4 * (total + classified.POOL_PAD) < 2 * n
    error = np.abs(decoded - coef) / steps
    assert error.max() <= 0.5 + 1e-6 and error.max() > 0.45
    # every cubic cell of every slot as scalar_cell decodes it (pool_cell): the host's q, cells across tiles included
    cells, expected = [], []
    for s, (nx, ny, nz, first) in enumerate(boxes):
        c = q[first:first + sizes[s]].reshape(nz, ny, nx)
        z, y, x = (a.ravel() for a in np.meshgrid(*(np.arange(order - 1, m) for m in (nz, ny, nx)), indexing="ij"))
        cells.append(np.stack([np.full(len(z), s), (z * ny + y) * nx + x], axis=1))
        r = np.arange(order)
        expected.append(c[(z[:, None] - r)[:, :, None, None], (y[:, None] - r)[:, None, :, None],
                          (x[:, None] - r)[:, None, None, :]].reshape(len(z), -1))  # from the last, CORNER_COEF's
    cells, expected = np.concatenate(cells).astype(np.int32), np.concatenate(expected)
    crossing = np.any(cells[:, 1:2] // boxes[cells[:, 0], :1] % boxes[cells[:, 0], 1:2] % 4 < order - 1, axis=1)
    assert crossing.mean() > 0.3  # cells whose rows lie in two tiles along y (and as many along z)
    assert np.any(boxes[:, 1:3] % 4)  # and slots whose last tiles are short of rows
    out = cla.zeros(tr.cc.queue, expected.size, np.float32)
    CELLS(pool_kernels(tr.cc), tr.cc.queue, (len(cells),), None, out=out, words=f.pool, quant=tr.quant,
          boxes=cla.to_device(tr.cc.queue, np.ascontiguousarray(f.boxes[:, 0])), cells=cla.to_device(tr.cc.queue,
                                                                                                     cells), j=order)
    np.testing.assert_array_equal(out.get().reshape(expected.shape), expected)
    scale, offset = world_to_fine_affine(order, wv.shape, wv.spacing, wv.origin)
    model = _content_field(wv)
    rng = np.random.default_rng(3)
    widest = 0.0
    for s in rng.choice(len(f.levels), 12, replace=False):
        blocks = rng.integers(0, SUPER, (4, 3))  # (z, y, x) in the brick
        for b in blocks:
            fine = ((f.bricks[s] * SUPER + b) * BLOCK)[::-1] + rng.uniform(0, BLOCK, (20, 3))  # (x, y, z)
            exact = brick_field(coef, f.boxes[s, 0], f.frames[s, 0], order, fine)
            quantized = brick_field(decoded, f.boxes[s, 0], f.frames[s, 0], order, fine)
            if f.levels[s] == 0:  # the finest bricks hold the model itself
                truth = model((fine - offset) / scale, False)[:, 0]
                np.testing.assert_allclose(exact, truth, rtol=0, atol=1e-6 * np.abs(truth).max() + 1e-7)
            assert np.abs(quantized - exact).max() <= quant["step"][s] / 2 * (1 + 1e-6) + 1e-12
            widest = max(widest, np.abs(quantized - exact).max() / max(quant["step"][s], 1e-30))
            lo, hi = tr.scalar.slot_range[(s, *b)]
            assert lo <= min(exact.min(), quantized.min()) and max(exact.max(), quantized.max()) <= hi
    assert widest > 0.01  # the decoded field does differ


def test_an_xray_tolerance_below_the_packed_pool_is_told():
    """A scalar model's X-ray through its packed pool (docs/raytracing.md §10, "Memory") is within half a step times
    the bricks' diagonal of the exact line integrals, whatever the tolerance: a tolerance below that is not met, and
    a render at it warns once, naming the floor and the unpacked wavelet field (diff22's fuzzing found such X-rays up
    to 147 times their tolerance, silently)."""
    from clwave.splat.reference import exact_xray

    data = np.random.default_rng(5).random((16, 16, 16)).astype(np.float32)
    wv = WaveletVolume.from_volume(clwave.Volume(data), wavelet="cubic", levels=0)
    cam = clwave.Camera(20, 10, size=12)
    exact = exact_xray(wv.reconstruct().data, 4, wv.spacing, wv.origin, cam.view(wv))
    tr = clwave.RayTracer(wv, content_clamp=False)
    limit = tr.scalar.step / 2 * np.linalg.norm(tr.bricks.shape) * 16  # the diagonal of the bricks' box
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        above = tr.render(cam, tolerance=10 * limit, absorption=False).image
    with pytest.warns(clwave.ClwaveWarning, match=r"packed to 16 bits .* field='wavelet'") as told:
        below = tr.render(cam, tolerance=limit / 100, absorption=False).image
        tr.render(cam, tolerance=limit / 100, absorption=False)
    assert len(told) == 1 and re.search(r"pixels may be off by up to .* more than the tolerance .* add --field "
                                        r"wavelet, which is not packed \(--tolerance is .* unless given\)",
                                        told[0].message.cli)
    assert np.abs(above - exact).max() <= 10 * limit and np.abs(below - exact).max() <= 1.01 * limit
    assert np.abs(below - exact).max() > limit / 100  # the tolerance is indeed not met
    exact_field = clwave.RayTracer(wv, content_clamp=False, field="wavelet").render(
        cam, tolerance=limit / 100, absorption=False, precision="double").image
    assert np.abs(exact_field - exact).max() <= limit / 100


def test_scalar_pool_in_a_scratch_file(monkeypatch):
    """Bricks in a scratch file (out-of-core passes, docs/raytracing.md §6) keep float coefficients: the
    post-classified image is within the tolerance of the float64 oracle there too, and a tracer of every detail's is
    bit for bit at full detail.  (A scalar pool on the device, one float a coefficient, fits wherever the expansion's
    work does: here it is made not to.)"""
    from clwave.raytrace import bricks

    fits = bricks._check_fits
    monkeypatch.setattr(bricks, "_check_fits", lambda *args: fits(*args) and None)  # never on the device
    vol = clwave.phantom("hydrogen", n=40)
    wv = clwave.WaveletVolume.from_volume(vol, wavelet="cubic", levels=2).threshold(keep=0.1)
    tr = clwave.RayTracer(wv, device_memory="10MiB")
    tf = clwave.TransferFunction.preset("hydrogen")
    cam = clwave.Camera(30, 20, size=8)
    res = tr.render(cam, tolerance=1e-3, transfer_function=tf)
    assert res.meta["pool"] == "scratch file"
    assert np.abs(res.image - classified_reference(wv, cam, tf, tracer=tr)).max() <= 1e-3
    lod = clwave.RayTracer(wv, device_memory="14MiB", lod=True).render(cam, tolerance=1e-3, transfer_function=tf)
    assert lod.meta["pool"] == "scratch file" and lod.meta["segments"] == res.meta["segments"]
    np.testing.assert_array_equal(lod.image, res.image)


def test_transfer_function_change_rebuilds_nothing(hydrogen, monkeypatch):
    """Another transfer function or window: no expansion, no new program, no new scalar range; only the table and
    the bounds (meta classify_seconds)."""
    from clwave.raytrace import classified, tracer

    wv, tr = hydrogen
    cam = clwave.Camera(30, 20, size=8)
    tr.render(cam, tolerance=1e-2, transfer_function=clwave.TransferFunction.preset("hydrogen"))
    calls = []
    monkeypatch.setattr(tracer, "build", lambda *a, **k: calls.append("build"))
    monkeypatch.setattr(classified.ScalarRange, "__init__", lambda *a, **k: calls.append("range"))
    programs_before = dict(tr.cc.programs.made)
    for tf in (clwave.TransferFunction.preset("hydrogen", window=(0.1, 0.9)), clwave.TransferFunction.preset("grey"),
               clwave.TransferFunction.preset("ct-bone", window=(0.0, 1.0))):
        res = tr.render(cam, tolerance=1e-2, transfer_function=tf)
        assert res.meta["transfer_function"] == tf.to_dict() and res.meta["classify_seconds"] > 0
    assert calls == [] and dict(tr.cc.programs.made) == programs_before
    again = tr.render(cam, tolerance=1e-2, transfer_function=clwave.TransferFunction.preset("ct-bone", window=(0, 1)))
    assert again.meta["classify_seconds"] == 0.0  # the same function: reused, nothing paid


def test_coarser_details_classify_the_coarser_model(monkeypatch):
    """RayTracer(lod=True) with a render-time transfer function: at detail L (levels, a screen-space error) each
    value within the tolerance of the float64 oracle of the model without the details of levels 1 .. L; a change
    of transfer function or detail rebuilds nothing (only that detail's ranges, once); refine() classifies every
    frame, its last bit for bit the full-detail render."""
    from clwave.raytrace import classified, tracer

    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=20), wavelet="cubic", levels=2)
    wv = wv.threshold(keep=0.2)
    tr = clwave.RayTracer(wv, lod=True)
    tf = clwave.TransferFunction.preset("hydrogen", window=(0.0, 0.6))
    cam = clwave.Camera(30, 20, size=6)
    full = tr.render(cam, tolerance=1e-3, transfer_function=tf).image
    calls = []
    monkeypatch.setattr(tracer, "build", lambda *a, **k: calls.append("build"))
    monkeypatch.setattr(classified.ScalarRange, "__init__", lambda *a, **k: calls.append("range"))
    for level in (1, 2):
        ref = classified_reference(wv, cam, tf, tracer=tr, detail=level)
        assert np.abs(ref - full).max() > 1e-2  # the details dropped show
        for tol in (1e-2, 1e-3):
            res = tr.render(cam, tolerance=tol, transfer_function=tf, detail=level)
            assert res.meta["detail"] == level and np.abs(res.image - ref).max() <= tol
    other = clwave.TransferFunction.preset("grey", window=(0.0, 0.5))
    coarse = tr.render(cam, tolerance=1e-2, transfer_function=other, detail=clwave.Detail(level=1, pixels=1e3))
    assert coarse.meta["detail"] == 2 and coarse.meta["classify_seconds"] > 0
    assert calls == [] and tr.expansions == 1 and len(tr.scalar.ranges) == 3  # full detail, 1 and 2
    frames = list(tr.refine(cam, tolerance=1e-3, transfer_function=tf))
    assert len(frames) > 1 and frames[0].detail > 0
    np.testing.assert_array_equal(frames[-1].image, full)


def test_post_converges_to_pre_for_smooth_transfer_functions():
    """A linear transfer function (alpha = 0.2 s, colour constant) makes pre-classification exact: the classified
    channels are linear in s, so the RGBA model is the scalar model times constants.  Both renders agree within
    the tolerances over the data's box, the outermost voxel centres, which post-classification integrates
    (docs/raytracing.md §10): the pre-classified render clipped to it."""
    vol = clwave.phantom("hydrogen", n=20)
    tf = clwave.TransferFunction([(0.0, 0.8, 0.5, 0.2, 0.0), (1.0, 0.8, 0.5, 0.2, 0.2)])
    scalar = clwave.WaveletVolume.from_volume(vol, levels=2)
    rgba = clwave.WaveletVolume.from_volume(tf.classify(vol), levels=2)
    cam = clwave.Camera(40, 10, size=10)
    post = clwave.raytrace(scalar, cam, tolerance=1e-3, transfer_function=tf, shading=False).image
    centres = 9.5 * np.array(vol.spacing[::-1])  # voxel 0 and 19 of 20 about the volume's centre
    pre = clwave.raytrace(rgba, cam, tolerance=1e-3, shading=False,
                          clip=clwave.Clip(np.asarray(vol.origin) - centres, np.asarray(vol.origin) + centres)).image
    assert post[..., 3].max() > 0.2
    assert np.abs(post - pre).max() <= 2e-3


def test_errors_and_default_transfer_function(tmp_path, hydrogen):
    wv, tr = hydrogen
    cam = clwave.Camera(30, 20, size=8)
    tf = clwave.TransferFunction.preset("hydrogen")
    with pytest.raises(InputError, match="transfer_function"):
        tr.render(cam)  # a scalar model without a transfer function
    with pytest.raises(InputError, match="X-ray"):
        tr.render(cam, transfer_function=tf, absorption=False)
    with pytest.raises(InputError, match="field='bspline'"):
        clwave.RayTracer(wv, field="wavelet").render(cam, transfer_function=tf)
    with pytest.raises(InputError, match="lod=True"):  # a coarser detail needs a tracer that holds it
        tr.render(cam, transfer_function=tf, detail=1)
    rgba = clwave.WaveletVolume.from_volume(tf.classify(clwave.phantom("hydrogen", n=16)), levels=1)
    with pytest.raises(InputError, match="4 channels"):
        clwave.raytrace(rgba, cam, transfer_function=tf)
    with pytest.raises(InputError, match=r"got list: make one with TransferFunction\(\[\(value, r, g, b, opacity\)"):
        tr.render(cam, transfer_function=[(0, 0, 0, 0, 0)])  # a preset's name is taken (tests/test_arrays27.py)
    # a scalar model made with a transfer function renders with it by default, also from its .clw file
    made = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=20), levels=2, transfer_function=tf)
    made.threshold(keep=0.1).save(tmp_path / "s.clw")
    opened = clwave.WaveletVolume.open(tmp_path / "s.clw")
    default = clwave.raytrace(opened, cam, tolerance=1e-2)
    given = clwave.raytrace(opened, cam, tolerance=1e-2, transfer_function=tf)
    assert default.meta["transfer_function"] == tf.to_dict()
    np.testing.assert_array_equal(default.image, given.image)


def test_command_line(tmp_path, capsys):
    """render scalar.clw --method raytrace --tf PRESET [--tf-window]; compress --tf PRESET --classify post stores the
    default; the mistakes are one line each."""
    from clwave.cli import main

    def run(*argv):
        code = main([str(a) for a in argv])
        out, err = capsys.readouterr()
        return code, out, err

    scalar, post = tmp_path / "s.clw", tmp_path / "p.clw"
    assert run("compress", "phantom:hydrogen:16", "--levels", "1", "-o", scalar)[0] == 0
    code, out, err = run("compress", "phantom:hydrogen:16", "--levels", "1", "--tf", "hydrogen", "--classify", "post",
                         "-o", post)
    assert code == 0 and "classify while ray tracing" in out
    assert WaveletVolume.open(post).channels == 1
    # as resolved records it: the opacity unit one voxel, the phantom's spacing 1
    assert WaveletVolume.open(post).transfer_function == clwave.TransferFunction.preset("hydrogen",
                                                                                       opacity_unit=1.0).to_dict()
    images = {}
    for name, argv in (("given", [scalar, "--tf", "hydrogen"]), ("default", [post]),
                       ("window", [scalar, "--tf", "hydrogen", "--tf-window", "0,0.5"]),
                       ("default-window", [post, "--tf-window", "0,0.5"])):
        raw = tmp_path / f"{name}.npy"
        code, out, err = run("render", *argv, "--method", "raytrace", "--size", "8", "--tolerance", "1e-2",
                             "--raw", raw, "-o", tmp_path / f"{name}.png")
        assert code == 0, err
        images[name] = np.load(raw)
    np.testing.assert_array_equal(images["given"], images["default"])
    np.testing.assert_array_equal(images["window"], images["default-window"])
    assert images["window"][..., 3].sum() > images["given"][..., 3].sum()  # a narrower window: more opaque
    rgba = tmp_path / "r.clw"
    assert run("compress", "phantom:hydrogen:16", "--levels", "1", "--tf", "hydrogen", "-o", rgba)[0] == 0
    for argv, needle in (([rgba, "--tf", "hydrogen"], "4 channels"),
                         ([scalar, "--tf", "hydrogen", "--field", "wavelet"], "--field bspline"),
                         ([scalar, "--tf-window", "0,1"], "--tf too"),
                         ([scalar], "--tf PRESET"),
                         ([scalar, "--tf", "ct-bone"], "values lie within")):  # HU on a model of other units
        code, out, err = run("render", *argv, "--method", "raytrace", "--size", "8", "-o", tmp_path / "x.png")
        assert code == 2 and needle in err and err.count("\n") == 1, err
    code, out, err = run("compress", "phantom:hydrogen:16", "--tf", "mri", "--classify", "post", "--tf-window", "auto",
                         "-o", tmp_path / "auto.clw")
    assert code == 0 and isinstance(WaveletVolume.open(tmp_path / "auto.clw").transfer_function["window"], list)
    assert not (tmp_path / "x.png").exists()
    code, out, err = run("progressive", scalar, "--method", "raytrace", "--tf", "ct-bone", "--size", "8",
                         "-o", tmp_path / "x.gif")
    assert code == 2 and "no value of this model any opacity" in err and "a window in the input's units" in err
    assert not (tmp_path / "x.gif").exists()


def test_slabs_composite_to_the_whole_image(hydrogen):
    """Post-classified slabs of bricks (each a RayTracer(region=...), as on a Dask cluster, docs/raytracing.md §7)
    composited front to back give the whole image within the tolerance."""
    from clwave.raytrace.regions import composite, slab_order, slabs

    wv, tr = hydrogen
    tf = clwave.TransferFunction.preset("hydrogen", window=(0.0, 0.7))
    cam = clwave.Camera(20, 60, size=10)
    whole = tr.render(cam, tolerance=1e-3, transfer_function=tf).image
    parts = slabs(wv, 2)
    images = [clwave.RayTracer(wv, region=tuple(int(v) for v in part)).render(
        cam, tolerance=1e-3 / len(parts), transfer_function=tf).image for part in parts]
    together = composite([images[i] for i in slab_order(wv, parts, cam)], True)
    assert len(parts) == 2 and whole[..., 3].max() > 0.1
    assert np.abs(together - whole).max() <= 2e-3


@pytest.mark.parametrize("wavelet", ["cubic", ["quadratic", "linear"]])
def test_expansion_of_one_channel_is_the_float4_ones(wavelet, monkeypatch):
    """A group of one channel is synthesised one float a coefficient (synthesis.lanes, four outputs a work-item
    along y and z) and a scalar model's pool holds one float a coefficient (bricks.build's scalar): the same bits as
    the float4 expansion's lane of that channel, its other lanes 0, and the same block bounds (a scalar model with
    its content mask, and a two-channel model of two one-channel groups: the second channel in lane 1)."""
    from clwave.device.memory import device_budget
    from clwave.raytrace import bricks, synthesis

    z, y, x = np.mgrid[:20, :22, :18] / 20.0
    blob = np.where((x - 0.5) ** 2 + (y - 0.5) ** 2 + (z - 0.4) ** 2 < 0.12, np.sin(9 * x) * np.cos(7 * y) + 1.5, 0.0)
    channels = 1 if isinstance(wavelet, str) else 2
    data = np.stack([blob, blob * z][:channels], axis=-1).astype(np.float32)
    wv = WaveletVolume.from_volume(clwave.Volume(data[..., 0] if channels == 1 else data), wavelet=wavelet,
                                   levels=2).threshold(keep=0.2)
    cc = ComputeContext.get()
    budget = device_budget(cc)
    one = bricks.build(wv, cc, budget, scalar=channels == 1)
    for module in (bricks, synthesis):
        monkeypatch.setattr(module, "lanes", lambda g: 4)
    four = bricks.build(wv, cc, budget)
    pool = four.pool.get()
    assert np.abs(pool).max() > 0.1 and np.array_equal(one.bounds, four.bounds)
    if channels == 1:
        assert one.pool.shape == (len(pool),) and np.array_equal(one.pool.get().view(np.uint32),
                                                                 pool[:, 0].view(np.uint32))
        assert not pool[:, 1:].any()
    else:
        assert np.array_equal(one.pool.get().view(np.uint32), pool.view(np.uint32))


def smooth_random(n=20, seed=7) -> clwave.Volume:
    """A smooth random scalar volume (Gaussian-filtered noise, every voxel content)."""
    from scipy.ndimage import gaussian_filter

    data = gaussian_filter(np.random.default_rng(seed).normal(size=(n, n, n)), 1.5)
    return clwave.Volume((data / np.abs(data).max()).astype(np.float32), spacing=(1.0, 0.9, 1.1))


@pytest.mark.parametrize("case", ["smooth-random", "hydrogen"])
def test_level_of_detail_keeps_full_detail_bit_for_bit(case, monkeypatch):
    """A scalar model's pool packed by a tracer of every detail: its full-detail slots are packed as a tracer of
    full detail alone packs them (their offset, step and q; docs/raytracing.md §10), so a render-time transfer
    function's full-detail image and segments are bit for bit the direct render's (window "auto" and given), and so
    is clwave.progressive's last frame; its coarse slots, whose range is wider, keep a step of their own, the widest
    coarse slot's range / 65535, and every decoded coefficient lies within half its slot's step of the float one."""
    from clwave.raytrace import classified

    floats, pack = [], classified.pack
    monkeypatch.setattr(classified, "pack", lambda scalar, *a: floats.append(scalar[:]) or pack(scalar, *a))
    if case == "hydrogen":
        wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=24), wavelet="cubic", levels=3)
        wv, tf = wv.threshold(keep=0.2), clwave.TransferFunction.preset("hydrogen", window=(0.0, 0.6))
    else:
        wv = clwave.WaveletVolume.from_volume(smooth_random(), wavelet="cubic", levels=2).threshold(keep=0.3)
        tf = clwave.TransferFunction.preset("grey")  # window "auto": from the full-detail slots' coefficients
    direct, lod = clwave.RayTracer(wv), clwave.RayTracer(wv, lod=True)
    step, steps = direct.quant.get()["step"], lod.quant.get()["step"]
    assert np.all(step == step[0]) and steps.max() > step[0]  # one step at full detail; the coarse slots' wider
    full = classified.full_detail_slots(lod.bricks)
    (one, q_one, _), (every, q_every, per) = decoded_pool(direct), decoded_pool(lod)
    picked = np.repeat(full, np.prod(lod.bricks.boxes[:, 0, :3].astype(np.int64), axis=1))
    np.testing.assert_array_equal(q_every[picked], q_one)
    np.testing.assert_array_equal(every[picked], one)
    np.testing.assert_array_equal(lod.quant.get()[["offset", "step"]][full], direct.quant.get()[["offset", "step"]])
    coef = floats[1][:len(every)].astype(np.float64)
    span = np.maximum.reduceat(coef, lod.bricks.boxes[:, 0, 3]) - np.minimum.reduceat(coef, lod.bricks.boxes[:, 0, 3])
    assert span[~full].max() / 65535 <= steps[~full][0] <= span[~full].max() / 65535 * (1 + 1e-6)
    assert np.all(steps[~full] == steps[~full][0]) and np.abs(every - coef).max(initial=0) > 0
    assert np.all(np.abs(every - coef) <= per / 2 * (1 + 1e-6))
    cam = clwave.Camera(30, 20, size=10)
    want = direct.render(cam, tolerance=1e-2, transfer_function=tf)
    got = lod.render(cam, tolerance=1e-2, transfer_function=tf)
    np.testing.assert_array_equal(got.image, want.image)
    assert got.meta["segments"] == want.meta["segments"] and got.meta["tf_window"] == want.meta["tf_window"]
    frames = list(clwave.progressive(wv, cam, method="raytrace", tolerance=1e-2, transfer_function=tf, tracer=lod))
    np.testing.assert_array_equal(frames[-1].image, want.image)


@pytest.mark.parametrize("wavelet", ["haar", "linear", "quadratic", "cubic", "quintic"])
def test_the_auto_windows_sample_is_the_field_at_voxel_centres_over_the_space_it_fills(wavelet):
    """``_sample`` (window "auto" at render time) takes the field's values, not its coefficients: a constant's
    coefficients give that constant (the B-splines' partition of unity), a ramp's the ramp at the voxel centres
    (they reproduce linear functions: the sampling kernel's 2h + 1 weights sum s w_s to h), at distinct points of
    the brick, its halo left out; and a level-1 brick counts as much as the space it fills (8 fine cells a point):
    two bricks of one volume each give half the points."""
    from clwave.model.bspline import wavelet_for
    from clwave.raytrace.classified import _sample

    half = (wavelet_for(wavelet).order - 1) // 2
    w = 2 * half + 1  # the sampling kernel's weights
    fine, coarse = 16 + w - 1 + 2, 8 + w - 1 + 2  # a brick's cells a side, its window, a halo of 2
    x = np.arange(fine)
    ramp = (x[None, None, :] + 100 * x[None, :, None] + 10000 * x[:, None, None]).astype(np.float32).ravel()
    boxes = np.array([[fine, fine, fine, 0], [coarse, coarse, coarse, fine ** 3]])
    scalar = np.concatenate([ramp, np.full(coarse ** 3, -7.0, np.float32)])
    values = _sample(scalar, boxes, np.array([True, True]), wavelet_for(wavelet), np.array([0, 1]))
    assert len(values) == 16 ** 3 + 8 ** 3  # as many as the bricks' own lattice points, spread by the space they fill
    constant = values == np.float32(-7.0)
    assert constant.sum() == len(values) // 2  # 16^3 fine cells each
    shift = half * 10101  # sum_s w_s s along each axis
    points = values[~constant] - shift
    digits = np.round(points).astype(np.int64)
    assert np.abs(points - digits).max() < 1e-2  # on the lattice (float32 sums of values up to 2e5)
    corners = {(int(d % 100), int(d // 100 % 100), int(d // 10000)) for d in digits}
    own = {(a, b, c) for a in range(1, 17) for b in range(1, 17) for c in range(1, 17)}  # a halo of 1 each side out
    assert len(corners) == len(digits) and corners <= own and {c for _, _, c in corners} == set(range(1, 17))


def test_the_auto_window_at_render_time_is_about_the_same_whatever_the_order():
    """The same smooth volume as cubic and quintic models: their "auto" windows at render time (the field's
    percentiles) agree within a tenth of the window (their thresholded models differ), where the coefficients'
    percentiles made the quintic's low end reach far below the data (its coefficients overshoot)."""
    z, y, x = np.mgrid[:32, :32, :32] / 32.0
    vol = clwave.Volume((np.exp(-((x - .5) ** 2 + (y - .5) ** 2 + (z - .5) ** 2) * 20)
                         + 0.05 * np.random.default_rng(0).standard_normal((32, 32, 32))).astype(np.float32))
    windows = {}
    for wavelet in ("cubic", "quintic"):
        wv = clwave.WaveletVolume.from_volume(vol, wavelet=wavelet, levels=1).threshold(keep=0.1)
        windows[wavelet] = np.array(clwave.RayTracer(wv).render(
            clwave.Camera(30, 20, 8), transfer_function=clwave.TransferFunction.preset("mri"))
            .meta["tf_window"])
    span = windows["cubic"][1] - windows["cubic"][0]
    assert np.abs(windows["quintic"] - windows["cubic"]).max() <= 0.1 * span, windows  # measured 0.074


def test_a_function_of_no_opacity_anywhere_is_told_so():
    """A transfer function whose every point has opacity 0 draws nothing whatever the window: its note says that,
    not to move a window (and names no function where it has no name)."""
    wv = WaveletVolume.from_volume(clwave.phantom("hydrogen", n=16), levels=1)
    meta = clwave.RayTracer(wv).render(clwave.Camera(30, 20, 8), transfer_function=clwave.TransferFunction(
        [(0, 1, 1, 1, 0), (1, 1, 1, 1, 0)])).meta
    assert meta["nothing_visible"] == ("the transfer function has opacity 0 at every point: give it some opacity (or "
                                       "another function)")
