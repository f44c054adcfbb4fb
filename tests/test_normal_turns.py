"""The normal's resolution rule of the shaded quadrature (``normal_turns``, ``series_turns`` in
cl/raytrace/quadrature.h; docs/raytracing.md §2) against the NumPy oracle (``reference._normal_turns``), decision by
decision, through a harness kernel (cl/raytrace/quadrature_check.cl)."""

import numpy as np
import pyopencl.array as cla
import pytest
from numpy.polynomial import chebyshev

from clwave.device import programs
from clwave.device.context import ComputeContext
from clwave.device.kernels import BUFFER, Kernel
from clwave.raytrace.reference import NORMAL_CHORD, _normal_turns
from clwave.raytrace.tracer import FAST_MATH

pytestmark = pytest.mark.opencl

LANES = Kernel("lane_turns", ("turns", BUFFER), ("lanes", BUFFER), ("shading", BUFFER), ("n", np.int32))
SPANS = Kernel("span_turns", ("turns", BUFFER), ("series", BUFFER), ("spans", BUFFER), ("counts", BUFFER),
               ("shading", BUFFER), ("n", np.int32))
K = 1 - NORMAL_CHORD ** 2 / 2  # a chord over 1/8 between unit normals: cos below K
# The kernel decides dot^2 < K^2 |w|^2 |v|^2 and |w|^2 > floor^2 after about a dozen roundings a side (the world
# gradient's components, the products and sums): its error is within 6 eps of the two sides' sum, the oracle's
# (float64) far within.  A decision whose exact margin is inside BAND eps of that sum is a rounding tie.
BAND = 16


def build(precision, samples=9):
    """(queue, harness kernels, real type) as the ray tracer builds its own (float32 with its fast math)."""
    cc = ComputeContext.get()
    if precision == "double" and not cc.queue.device.double_fp_config:
        pytest.skip("no float64 on this device")
    double = precision == "double"
    ks = programs.build(cc, ["raytrace/quadrature_check.cl"],
                        dict(CLW_SAMPLES=samples, CLW_GROUPS=1, CLW_ORDERS=6 if samples > 10 else 4,
                             CLW_MAX_DEPTH=16, CLW_SHADE=None, **({"CLW_DOUBLE": None} if double else {})),
                        () if double else FAST_MATH)
    return cc.queue, ks, np.float64 if double else np.float32


def decisions(world, floor, eps):
    """The rule between neighbouring rows of exact world gradients (..., P, 3), from the exact margins (long double):
    (its decision, whether that is a rounding tie (within BAND eps of the kernel's threshold), and the chord's margin
    in bands: the relative difference of dot^2 and K^2 |w|^2 |v|^2, inf where the normals are 90 degrees or more
    apart), each (..., P - 1)."""
    w, v = np.asarray(world[..., :-1, :], np.longdouble), np.asarray(world[..., 1:, :], np.longdouble)
    dot, ww, vv, f2 = (w * v).sum(-1), (w * w).sum(-1), (v * v).sum(-1), np.longdouble(floor) ** 2
    with np.errstate(invalid="ignore", divide="ignore"):
        chord = np.where(dot > 0, (dot * dot - K * K * ww * vv) / (dot * dot + K * K * ww * vv), -np.inf) / (BAND * eps)
    lit = np.minimum((ww - f2) / (ww + f2), (vv - f2) / (vv + f2)) / (BAND * eps)
    return (chord < 0) & (lit > 0), (chord < 1) & (lit > -1) & ~((chord < -1) & (lit > 1)), np.abs(chord)


def rotate(n, theta, rng):
    """Unit normals n (N, 3) turned by theta (N,) about random axes across them."""
    axis = np.cross(n, rng.normal(size=n.shape))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    return n * np.cos(theta)[:, None] + np.cross(axis, n) * np.sin(theta)[:, None]


def gradient_sets(rng, count, floor, eps):
    """``count`` sets of 9 world gradients (p = 0..8) whose normals turn from point to point by chords spread about
    1/8 (log-normally, and within 1e-2 of it down to the rounding band), some flipped; lengths from half the floor to
    10^4 times it, some zero and some within 1e-3 of the floor down to the band."""
    theta_c = 2 * np.arcsin(NORMAL_CHORD / 2)
    # a chord 1 + d times 1/8 moves the squares' relative margin by about d / (64 K): the band is 64 K BAND eps of it
    near = 10.0 ** rng.uniform(np.log10(64 * K * BAND * eps), -2, (count, 9)) * rng.choice([-1, 1], (count, 9))
    theta = theta_c * np.where(rng.random((count, 9)) < 0.3, np.exp(rng.normal(0, 0.3, (count, 9))), 1 + near)
    theta[rng.random((count, 9)) < 0.05] = np.pi  # the normal flips
    n = [rng.normal(size=(count, 3))]
    n[0] /= np.linalg.norm(n[0], axis=1, keepdims=True)
    for p in range(1, 9):
        n.append(rotate(n[-1], theta[:, p], rng))
    length = floor * np.exp(rng.uniform(np.log(0.5), np.log(1e4), (count, 9)))
    at_floor = rng.random((count, 9)) < 0.1
    length[at_floor] = floor * (1 + 10.0 ** rng.uniform(np.log10(BAND * eps), -3, at_floor.sum())
                                * rng.choice([-1, 1], at_floor.sum()))
    length[rng.random((count, 9)) < 0.05] = 0  # a vanishing gradient
    return np.stack(n, axis=1) * length[..., None]


def edge_sets(floor):
    """Deterministic sets (scale 1) and the rule's decisions on their 8 pairs: a lit gradient beside a vanishing one,
    its flip, a flip onto a gradient under the floor; gradients exactly at the floor (flat: the rule asks for more
    than the floor) beside their flips, and three times the floor flipped."""
    w, at = np.array([0.6, -0.48, 0.64]) * floor * 50, np.array([floor, 0.0, 0.0])
    return (np.array([[w, 0 * w, w, -w, w, -w / 100, w, w, w], [at, -at, at, -3 * at, 3 * at, -at, at, -at, -at]]),
            np.array([[0, 0, 1, 1, 0, 0, 0, 0], [0, 0, 0, 1, 0, 0, 0, 0]], bool))


@pytest.mark.parametrize("precision", ["single", "double"])
def test_normal_turns_follows_the_oracle_pair_by_pair(precision):
    """normal_turns on 2,000 random sets of 9 gradients, each neighbouring pair alone (the other lanes repeat its two
    points, so only that pair can turn): the kernel's decision is the oracle's for every pair but the rounding ties,
    which ``decisions`` finds from the exact margins (of the world gradients the kernel is given, in long double),
    and decided pairs reach within 100 bands of the threshold on both sides.  No two vectors of floating-point numbers
    are exactly 1/8 apart as normals (|w x v|^2 would be 255/16384 |w|^2 |v|^2, and 255 m^2 is no sum of three
    squares), so the threshold is met only within rounding; the edge cases (``edge_sets``) are decided exactly, a
    gradient exactly at the floor flat in both.  Then the whole sets: each panel's bit is the oracle's on its 5
    points (lanes 0..7: p = 1..8, lane 8: p = 0; lanes 9.. unused, NaN here)."""
    queue, ks, real = build(precision)
    eps = np.finfo(real).eps
    rng = np.random.default_rng(30)
    count, floor = 2000, float(real(3e-4))
    edges, edge_turns = edge_sets(floor)
    world = np.concatenate([gradient_sets(rng, count, floor, eps), edges])
    scale = np.ones((len(world), 3))
    scale[:count] = rng.uniform(0.5, 2.0, (count, 3))
    scale = scale.astype(real)
    fine = (world / scale[:, None, :]).astype(real)
    world = fine.astype(np.longdouble) * scale[:, None, :]  # the world gradients the kernel is given, exactly
    exact, tie, margin = decisions(world, floor, eps)
    oracle = _normal_turns(np.stack([world[:, :-1], world[:, 1:]], axis=2).astype(np.float64), floor)
    assert np.array_equal(oracle[~tie], exact[~tie])  # the oracle is the rule, away from its own rounding

    def run(points):
        """normal_turns of sets of 9 points (N, 9, 3) (p = 0..8), the scale of their set's row."""
        lanes = np.full((len(points), 3, 16), np.nan, real)
        lanes[:, :, :9] = np.concatenate([points[:, 1:], points[:, :1]], axis=1).transpose(0, 2, 1)
        shading = np.c_[np.repeat(scale, len(points) // len(scale), axis=0), np.full(len(points), floor)]
        out = cla.empty(queue, len(points), np.int32)
        LANES(ks, queue, (len(points),), None, turns=out, lanes=cla.to_device(queue, lanes),
              shading=cla.to_device(queue, shading.astype(real)), n=len(points))
        return out.get()

    # pair (p - 1, p) alone: points q < p take point p - 1's gradient, the others point p's
    q, panel_bit = np.arange(9), np.where(np.arange(1, 9) <= 4, 1, 2)
    bits = run(fine[:, [np.where(q < p, p - 1, p) for p in range(1, 9)]].reshape(-1, 9, 3)).reshape(len(fine), 8)
    kernel = (bits & panel_bit) > 0
    assert not np.any(bits & ~panel_bit)  # the other panel's bit stays clear
    assert np.array_equal(kernel[~tie], oracle[~tie]), np.argwhere((kernel != oracle) & ~tie)[:5]
    assert np.array_equal(kernel[count:], edge_turns) and np.array_equal(oracle[count:], edge_turns)
    assert tie.mean() < 0.1 and 0.3 < oracle[~tie].mean() < 0.7
    close = ~tie & (margin < 100)
    assert np.sum(close & oracle) >= 20 and np.sum(close & ~oracle) >= 20
    # the whole sets: bit 0 from points 0..4, bit 1 from 4..8; open where a tie could decide the panel
    bits = run(fine)
    for panel in (0, 1):
        pairs = slice(4 * panel, 4 * panel + 4)
        sure = (oracle[:, pairs] & ~tie[:, pairs]).any(axis=1)
        open_ = ~sure & tie[:, pairs].any(axis=1)
        want = _normal_turns(world[:, 4 * panel: 4 * panel + 5].astype(np.float64), floor)
        assert np.array_equal(want[~open_], sure[~open_])
        assert np.array_equal(((bits >> panel) & 1).astype(bool)[~open_], want[~open_])


@pytest.mark.parametrize("precision,samples", [("single", 9), ("double", 9), ("single", 16)])
def test_series_turns_follows_the_oracle(precision, samples):
    """series_turns: the gradient's Chebyshev series (degree 8, or 14 for order 6) summed at the points
    l + (r - l) p / count of a span, count 4 (one panel: bit 1 stays clear) or 8 (two), and normal_turns on them:
    the oracle's decision on each panel's 5 points but the rounding ties.  Small whole coefficients (times a power of
    two) summed at quarter points are exact in float32 (Clenshaw's partial sums need at most 23 bits), so the kernel
    and the oracle see the same gradients and only the rule's own arithmetic rounds."""
    queue, ks, real = build(precision, samples)
    NG = 15 if samples > 10 else 9
    eps = np.finfo(real).eps
    rng = np.random.default_rng(31)
    n, floor = 3000, float(real(0.05))
    series = rng.integers(-4, 5, (n, NG, 3)).astype(float)
    slow = rng.random(n) < 0.7  # and gradients that turn slowly: a large constant, a little else
    series[slow, 1:] = rng.integers(-1, 2, (slow.sum(), NG - 1, 3)) * (rng.random((slow.sum(), NG - 1, 3)) < 0.3)
    series[slow, 0] = rng.integers(8, 33, (slow.sum(), 3)) * rng.choice([-1, 1], (slow.sum(), 3))
    series *= 2.0 ** rng.integers(-6, 7, n)[:, None, None]
    spans = np.array([(-1, 0, 4), (0, 1, 4), (-0.5, 0.5, 4), (-1, 1, 4), (-1, 1, 8)])[rng.integers(0, 5, n)]
    scale = rng.uniform(0.5, 2.0, (n, 3)).astype(real)
    out = cla.empty(queue, n, np.int32)
    SPANS(ks, queue, (n,), None, turns=out, series=cla.to_device(queue, series.astype(real)),
          spans=cla.to_device(queue, np.ascontiguousarray(spans[:, :2], real)),
          counts=cla.to_device(queue, spans[:, 2].astype(np.int32)),
          shading=cla.to_device(queue, np.c_[scale, np.full(n, floor)].astype(real)), n=n)
    bits = out.get()
    four = spans[:, 2] == 4
    assert np.all(bits[four] < 2)
    x = spans[:, :1] + (spans[:, 1:2] - spans[:, :1]) * np.minimum(np.arange(9) / spans[:, 2:], 1)  # past the count:
    grads = np.einsum("npm,nmc->npc", chebyshev.chebvander(x, NG - 1), series)  # the last point again (exact sums)
    world = grads.astype(np.longdouble) * scale[:, None, :]
    exact, tie, _ = decisions(world, floor, eps)
    for panel in (0, 1):
        rows = np.ones(n, bool) if panel == 0 else ~four
        sl = slice(4 * panel, 4 * panel + 4)
        sure = (exact[:, sl] & ~tie[:, sl]).any(axis=1)
        open_ = ~sure & tie[:, sl].any(axis=1)
        want = _normal_turns(world[:, 4 * panel: 4 * panel + 5].astype(np.float64), floor)
        got = ((bits >> panel) & 1).astype(bool)
        assert np.array_equal(want[rows & ~open_], sure[rows & ~open_])
        assert np.array_equal(got[rows & ~open_], want[rows & ~open_])
        assert 0.2 < want[rows].mean() < 0.8 and open_[rows].mean() < 0.01, (want[rows].mean(), open_[rows].mean())
