"""NumPy float64 reference of the ray tracer's quadrature (``cl/raytrace/raytrace.cl``), for tests.

The same algorithm, written independently of the kernel: the field comes from
:meth:`WaveletVolume.evaluate` / :meth:`~WaveletVolume.gradient` (closed-form wavelet
bases) instead of the device's fine B-spline grids; segments are the knot planes of
the lattice; alpha's exact Chebyshev series gives ``A``; ``∫ q e^{-A}`` comes from
adaptive Simpson with two initial panels and the normal's resolution test (docs/raytracing.md §2), a ray's panels of
one depth at once; early termination and the skipping of nearly empty blocks as in the kernel.  Slow (Python per
segment for the march): tiny volumes and images only.  :class:`Field` renders another field than the model's, e.g.
a coarser detail's (docs/raytracing.md §8).
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np
from numpy.polynomial import chebyshev

from ..device.constants import BLOCK, SUPER
from ..model.geometry import world_to_fine, world_to_fine_affine
from ..model.transform import Band, band_sum, synthesize
from .lod import occupancy
from .quadrature import sample_points
from .shading import Phong, light_directions
from .tracer import SIMPSON_DEPTH, RayTracer


class Field(NamedTuple):
    """A field for :func:`raytrace_reference` other than the model's."""

    evaluate: Callable  # f(world points (N, 3), derivative): the values (N, C), or world gradients (N, C, 3)
    box: tuple  # (lo, hi) (x, y, z) in grid-0 fine coordinates: the field is zero outside
    grad_floor: float  # the render's flat gradients (RayTracer.grad_floor of the field's q_bound)
    knots: tuple  # where its polynomial pieces meet: planes at + h k (grid-0 fine) on every axis, per (h, at)


def raytrace_reference(wv, camera, tolerance=1e-3, lights=None, shading=True, absorption=True,
                       tracer: RayTracer | None = None, field: Field | None = None, clip=None) -> np.ndarray:
    """(H, W, 4) float64 image as :func:`clwave.raytrace` computes it, or (H, W, C) line integrals.

    ``tracer`` supplies the clip box, occupancy lattice and emission bound the kernel used.  ``field``: a
    :class:`Field` other than the model's (a coarser detail's, docs/raytracing.md §8); the tracer's bounds are not
    its bounds, so nothing is skipped and no ray stops early.  ``clip``: a :class:`~clwave.model.clip.Clip`, each
    ray's interval cut to it in world coordinates (:func:`_cut`).
    """
    tr = tracer or RayTracer(wv)
    view = camera.view(wv)
    H, W = view.size
    orders = tr.orders
    h = 0.5 if len({o % 2 for o in orders}) > 1 else 1.0
    phong = (shading if isinstance(shading, Phong) else Phong()) if shading else None
    if tr.orders[tr.alpha_group] == 1 or not absorption:
        phong = None
    light_dirs = light_directions(lights, view.n)
    gain = (phong.ambient + (phong.diffuse + phong.specular) * len(light_dirs)) if phong else 1.0
    regions = None if field else _Regions(tr.block_bound.get(), tr.occ_origin, tr.super_bound_host, tr.super_origin,
                                          tr.coarse_bound(tolerance))
    box, lattices = (field.box, field.knots) if field else (tr.box, [(h, 0.0)])
    scale, offset = world_to_fine_affine(orders[0], wv.shape, wv.spacing, wv.origin)
    # the kernel's points (the field is the same polynomial), a hair inside the segment's ends: there a Haar channel
    # takes its value from inside the segment, as the kernel's one piece per segment does (docs/raytracing.md §3)
    xi = sample_points(3 * (max(orders) - 1)) * (1.0 - 2.0 ** -32)
    n_samples = len(xi)
    out = np.zeros((H, W, 4 if absorption else wv.channels))
    rays = []
    for r, c in np.ndindex(H, W):
        p, w = _ray(view, r, c)
        t0, t1 = _cut(p, w, *_clip(p * scale + offset, w * scale, box, view.perspective), clip)
        if t1 > t0:
            knots = np.unique(np.concatenate([_knots(p * scale + offset, w * scale, t0, t1, *lattice)
                                              for lattice in lattices]))
            lo, hi = knots[:-1][knots[1:] > knots[:-1]], knots[1:][knots[1:] > knots[:-1]]
            rays.append((r, c, w, p * scale + offset, (lo + hi) / 2, (hi - lo) / 2, t0, t1,
                         p + ((lo + hi)[:, None] / 2 + (hi - lo)[:, None] / 2 * xi).reshape(-1, 1) * w))
    if not rays:
        return out
    points = np.concatenate([ray[-1] for ray in rays])  # one evaluation for every sample of every ray
    evaluate = field.evaluate if field else \
        _content_field(wv) if tr.field == "bspline" and wv.content_mask is not None else _model_field(wv)
    fields = np.split(evaluate(points, False), np.cumsum([len(ray[-1]) for ray in rays])[:-1])
    grads = np.split(evaluate(points, True)[:, 3, :], len(fields) and np.cumsum([len(f) for f in fields])[:-1]) \
        if phong else [None] * len(rays)
    floor = field.grad_floor if field else tr.grad_floor()
    for (r, c, w, x0, mid, rad, t0, t1, _), values, grad in zip(rays, fields, grads):
        values = values.reshape(len(mid), n_samples, -1)
        grad = None if grad is None else grad.reshape(len(mid), n_samples, 3)
        empty = ~_reached(tr, x0 + mid[:, None] * (w * scale))  # segments no content reaches: empty
        values[empty] = 0.0
        if grad is not None:
            grad[empty] = 0.0
        blocks = _BlockSkip(regions, x0, w * scale, t0, t1, absorption, tolerance, gain) if regions else _NoSkip()
        if not absorption:
            keep = [s for s in range(len(mid)) if not blocks.skip(mid[s] - rad[s], mid[s] + rad[s], 1.0)]
            out[r, c] = np.einsum("s,sc->c", rad[keep], _integral(_fit(values[keep], xi)))
            continue
        values[..., 3] = np.maximum(values[..., 3], 0.0)  # alpha clamped at the samples, q where it is used
        out[r, c] = _emission_absorption(values, grad, xi, mid, rad, t1 - t0, tolerance, gain,
                                         phong, light_dirs, w, blocks, floor)
    return out


class _Regions:
    """The kernel's bounds on |field|: a superblock of SUPER^3 blocks bounded by at most ``coarse`` is
    one region, any other block its own."""

    def __init__(self, block_bound, origin, super_bound, super_origin, coarse):
        # looked up in this order: the superblock, then (unless it is coarse) the block
        self.levels = [(super_bound, np.asarray(super_origin), BLOCK * SUPER), (block_bound, np.asarray(origin), BLOCK)]
        self.coarse = coarse

    def lookup(self, x0, d, a, b, t1):
        """(bound, where the ray x0 + t d leaves the region) of the region holding the midpoint of [a, b]."""
        x = x0 + (a + b) / 2 * d
        for bound, origin, size in self.levels:
            cell = np.floor(x / size).astype(int)  # (x, y, z)
            idx = cell[::-1] - origin
            value = float(bound[tuple(idx)]) if np.all((idx >= 0) & (idx < bound.shape)) else 0.0
            if size == BLOCK or value <= self.coarse:
                nz = d != 0
                return value, min(t1, np.min(((cell[nz] + (d[nz] > 0)) * size - x0[nz]) / d[nz]))


class _BlockSkip:
    """The kernel's empty-space rule along one ray: skip a region while its worst case fits the budget.

    ``rest(t)`` is the region bounds integrated along the ray beyond t (the kernel's R), kept as
    the whole ray's integral less what the march has passed.
    """

    def __init__(self, regions, x0, d, t0, t1, absorption, tol, gain):
        self.regions, self.x0, self.d, self.t1 = regions, x0, d, t1
        self.absorption, self.budget = absorption, tol / 4 if absorption else tol / 2
        self.gain, self.until, self.value = gain, -np.inf, 0.0
        pieces = _knots(x0, d, t0, t1, BLOCK)
        self.total = sum(self._lookup(a, b)[0] * (b - a) for a, b in zip(pieces[:-1], pieces[1:]))
        self.slack, self.consumed = self.total * 1e-4, 0.0

    def _lookup(self, a, b):
        return self.regions.lookup(self.x0, self.d, a, b, self.t1)

    def skip(self, a, b, T) -> bool:
        """Whether segment [a, b] is skipped (it lies in a block skipped from an earlier point, or its own)."""
        if b <= self.until + 1e-9 * max(1.0, abs(self.until)):
            return True
        self.value, texit = self._lookup(a, b)
        texit = max(texit, b)
        cost = self.value * (texit - a)
        if self.absorption:
            rest_after = max(self.total - self.consumed - cost, 0.0) + self.slack
            cost *= T * (self.gain * (1 + rest_after) + 1)
        if cost <= self.budget:
            self.budget -= cost
            self.consumed += self.value * (texit - a)
            self.until = texit
            return True
        return False

    def passed(self, a, b) -> float:
        """Count the evaluated segment [a, b] as passed; the bound integral left beyond it."""
        self.consumed += self.value * (b - a)
        return max(self.total - self.consumed, 0.0) + self.slack


class _NoSkip:
    """No bounds: nothing skipped, no ray stopped early."""

    def skip(self, a, b, T) -> bool:
        return False

    def passed(self, a, b) -> float:
        return np.inf


def _model_field(wv):
    """The field from the closed-form wavelet bases (the band sum, never the synthesis the bricks come from):
    ``f(points, derivative)``."""
    return lambda points, derivative: wv.gradient(points, "bands") if derivative else wv.evaluate(points, "bands")


def _content_field(wv, level=0):
    """The B-spline backend's field for a model that knows its content: the fine B-spline coefficients
    of the host's real-line synthesis, zero on empty voxels (docs/raytracing.md §4); at detail ``level`` > 0
    (§8) the level's coefficients from the bands above it, zero where unoccupied (any model)."""
    parts = []
    for gi, g in enumerate(wv.groups):
        if level == 0:
            coeffs, start = wv.fine_coefficients(gi)
            coeffs = coeffs * wv.content_mask.box(start, coeffs.shape[:3])[..., None]
        else:
            coeffs, start = synthesize(g.wavelet, *zip(*[(b, d) for b, d in zip(g.bands, g.dense_bands())
                                                         if b.key == "aaa" or b.level > level]))
            if wv.content_mask is not None:
                coeffs = coeffs * occupancy(wv.content_mask, g.wavelet, level, start, coeffs.shape[:3])[..., None]
        parts.append((g, coeffs, start))
    return spline_field(wv, parts, level)


def spline_field(wv, parts, level=0):
    """The field of B-spline coefficients on the level-``level`` lattice, in closed form: ``parts`` holds per group
    ``(group, coefficients (Z, Y, X, channels), start)``, coefficient k's B-spline on that lattice's cells
    ``start + k ..`` (the lattice of :func:`clwave.model.transform.synthesize`).  Returns ``f(points, derivative)``:
    at world points (N, 3), the values (N, C), or the world gradients (N, C, 3) (x, y, z)."""
    def field(points, derivative):
        out = np.zeros((len(points), wv.channels, 3) if derivative else (len(points), wv.channels))
        for g, coeffs, start in parts:
            fine = world_to_fine(points, g.wavelet.order, wv.shape, wv.spacing, wv.origin) - 2.0 ** level * np.array(
                start, float)
            value = band_sum(g.wavelet, Band(level, "aaa", coeffs.shape[:3], 0), coeffs, fine, derivative)
            out[:, list(g.channels)] = value[..., ::-1] / np.asarray(wv.spacing)[::-1] if derivative else value
        return out
    return field


def _reached(tr, x) -> np.ndarray:
    """Per grid-0 fine point (N, 3) as (x, y, z): whether the tracer's content cells reach its cell."""
    if tr.content_cells is None:
        return np.ones(len(x), bool)
    k = np.floor(x[:, ::-1]).astype(np.int64) - tr.content_origin  # (z, y, x)
    inside = np.all((k >= 0) & (k < tr.content_cells.shape), axis=1)
    out = np.zeros(len(x), bool)
    out[inside] = tr.content_cells[tuple(k[inside].T)] > 0
    return out


def _ray(view, r, c):
    H, W = view.size
    pc, pr = c + 0.5 - W / 2, H / 2 - r - 0.5
    if view.perspective:
        su, sv = view.principal[0] + pc * view.slope[0], view.principal[1] + pr * view.slope[1]  # View.slopes
        w = -view.n + su * view.u + sv * view.v
        return view.eye, w / np.linalg.norm(w)
    return view.target + pc * view.pixel * view.u + pr * view.pixel * view.v, -view.n


def _clip(x0, d, box, perspective):
    t0, t1 = (0.0 if perspective else -np.inf), np.inf
    for a in range(3):
        if d[a] == 0:
            if not box[0][a] <= x0[a] <= box[1][a]:
                return 0.0, -np.inf
            continue
        ta, tb = (box[0][a] - x0[a]) / d[a], (box[1][a] - x0[a]) / d[a]
        t0, t1 = max(t0, min(ta, tb)), min(t1, max(ta, tb))
    return t0, t1


def _cut(p, w, t0, t1, clip):
    """[t0, t1] of the world ray p + t w cut to ``clip``'s box and half-spaces, in world coordinates (the kernel cuts
    its box in grid-0 fine ones, its half-spaces from the unit normals of ``Clip.half_spaces``)."""
    if clip is None:
        return t0, t1
    if clip.lo is not None:
        a, b = _clip(p, w, (clip.lo, clip.hi), False)
        t0, t1 = max(t0, a), min(t1, b)
    for point, normal in clip.planes:
        at, rate = np.dot(normal, p - np.asarray(point)), np.dot(normal, w)  # the side kept: n . (x - point) >= 0
        if rate == 0:
            t1 = t1 if at >= 0 else -np.inf
        elif rate > 0:
            t0 = max(t0, -at / rate)
        else:
            t1 = min(t1, -at / rate)
    return t0, t1


def _knots(x0, d, t0, t1, h, at=0.0):
    """The ray parameters in [t0, t1] of the ray x0 + t d where it meets the planes at + h k, and t0, t1."""
    ts = [np.array([t0, t1])]
    for a in range(3):
        if d[a] != 0:
            ends = sorted([(x0[a] + t0 * d[a] - at) / h, (x0[a] + t1 * d[a] - at) / h])
            planes = np.arange(np.floor(ends[0]), np.ceil(ends[1]) + 1) * h + at
            t = (planes - x0[a]) / d[a]
            ts.append(t[(t > t0) & (t < t1)])
    return np.unique(np.concatenate(ts))


def _fit(samples, xi):
    """Chebyshev series (S, N, C) of the polynomials through samples (S, N, C) at the N points xi."""
    to_series = np.linalg.inv(chebyshev.chebvander(xi, len(xi) - 1))
    return np.einsum("mk,skc->smc", to_series, samples)


def _integral(series):
    """∫_{-1}^{1} of each series: sum over even m of a_m 2/(1 - m^2)."""
    m = np.arange(series.shape[1])
    weights = np.where(m % 2 == 0, 2.0 / (1.0 - m ** 2.0 + (m % 2)), 0.0)
    return np.einsum("smc,m->sc", series, weights)


def _emission_absorption(values, grad, xi, mid, rad, total, tol, gain, phong, lights, w, blocks, floor):
    """One ray's colour and opacity from its segments' samples (values: alpha clamped; grad: alpha's gradient)."""
    series = _fit(values, xi)  # (S, n, 4)
    n = series.shape[1]
    A = chebyshev.chebint(series[..., 3], lbnd=-1, axis=1)  # (S, n + 1): alpha's antiderivative, 0 at xi = -1
    # the field's, the gradient's and the optical depth's series, summed at once where Simpson needs them
    stacked = np.zeros((len(rad), n + 1, 8))
    stacked[:, :n, :4], stacked[:, :, 7] = series, A
    if grad is not None:
        stacked[:, :n, 4:7] = _fit(grad, xi)
    T, color = 1.0, np.zeros(3)
    shade_budget = tol * 3 / 8  # when shading: three quarters of the quadrature's half
    quadrature_share = tol / 8 if phong is not None else tol / 2
    if phong is not None:  # the midpoint of the shading range, when its error fits the shading budget
        u = _at(stacked, -1.0 + np.arange(9) / 4.0)  # (S, 9, 8) at the quarter points
        unshaded = np.maximum(u[..., :4], 0.0) * np.exp(-rad[:, None, None] * u[..., 7:])  # q_RGB, alpha
        s4 = (unshaded[:, 0] + 4 * unshaded[:, 1:8:2].sum(1) + 2 * unshaded[:, 2:8:2].sum(1) + unshaded[:, 8]) / 12
        s2 = (unshaded[:, 0] + 4 * unshaded[:, 2] + 2 * unshaded[:, 4] + 4 * unshaded[:, 6] + unshaded[:, 8]) / 6
        ds, nl = np.abs(s4 - s2), len(lights)
        diffuse_mid, specular_mid = phong.ambient + phong.diffuse * nl / 2, phong.specular * nl / 2
        err = (phong.diffuse * nl / 2 * (s4[:, :3] + ds[:, :3]) + specular_mid * (s4[:, 3:] + ds[:, 3:])
               + diffuse_mid * ds[:, :3] + specular_mid * ds[:, 3:]).max(axis=1)
        midpoint = diffuse_mid * s4[:, :3] + specular_mid * s4[:, 3:]
    whole = []  # the segments Simpson integrates: (segment, T radius, tolerance per unit of xi)
    for s in range(len(rad)):
        if blocks.skip(mid[s] - rad[s], mid[s] + rad[s], T):
            continue
        if phong is not None and T * rad[s] * err[s] <= shade_budget:
            shade_budget -= T * rad[s] * err[s]
            color += T * rad[s] * midpoint[s]
        elif series[s].any():  # (where the field is zero, so is the integrand)
            whole.append((s, T * rad[s], quadrature_share * 2 / total / T))
        T, done = _passed(T, rad[s], A[s], blocks, mid[s], gain, tol)
        if done:
            break
    if whole:
        segments, weight, seg_tol = (np.array(v) for v in zip(*whole))

        def integrand(k, x):
            """q e^{-A} (len(k), 3) of segment k[i] at x[i]."""
            f = _at(stacked[k], x[:, None])[:, 0]
            q = np.maximum(f[:, :3], 0.0)
            if phong is not None:
                q = _shade(q, np.maximum(f[:, 3], 0.0), f[:, 4:7], phong, lights, w, floor)
            return q * np.exp(-rad[k] * f[:, 7])[:, None]

        def turns(k, a, b):
            if phong is None:
                return np.zeros(len(k), bool)
            return _normal_turns(_at(stacked[k], np.linspace(a, b, 5, axis=1))[..., 4:7], floor)

        color += weight @ _simpson(integrand, seg_tol, turns, segments)
    return np.append(color, 1.0 - T)


def _at(series, x):
    """Chebyshev series (..., m, C) at points x (P,), or per series (..., P): (..., P, C)."""
    return np.einsum("...pm,...mc->...pc", chebyshev.chebvander(x, series.shape[-2] - 1), series)


def _passed(T, rad, A, blocks, mid, gain, tol):
    """T past the segment, and whether the ray stops there: what is left can change no output by tol/4."""
    T *= np.exp(-rad * chebyshev.chebval(1.0, A))
    left = blocks.passed(mid - rad, mid + rad)
    return T, T * max(min(1.0, left), gain * left) <= tol / 4


def _shade(q, alpha, grad, phong, lights, w, floor):
    """Phong's eq. 4 with the outward normal -grad/|grad| (world gradient of alpha); unlit at |grad| <= floor.
    At one point or several: q (..., 3), alpha (...), grad (..., 3)."""
    length = np.linalg.norm(grad, axis=-1)
    lit = length > floor
    n = -grad / np.where(lit, length, 1.0)[..., None]
    diffuse = specular = np.zeros_like(length)
    for light in lights:
        halfway = (light - w) / np.linalg.norm(light - w)
        diffuse = diffuse + np.where(lit, np.maximum(n @ light, 0.0), 0.0)
        specular = specular + np.where(lit, np.maximum(n @ halfway, 0.0) ** phong.shininess, 0.0)
    return q * (phong.ambient + phong.diffuse * diffuse)[..., None] + phong.specular * (alpha * specular)[..., None]


NORMAL_CHORD = 0.125  # the kernel's (cl/raytrace/quadrature.h)


def _normal_turns(grads, floor) -> np.ndarray:
    """Whether the normal -grad/|grad| moves by more than NORMAL_CHORD between neighbouring rows of ``grads``
    (..., P, 3) (world gradients at a panel's points) where neither is flat (docs/raytracing.md §2): (...) bool."""
    length = np.linalg.norm(grads, axis=-1)
    normals = grads / np.maximum(length, np.finfo(float).tiny)[..., None]
    chords = np.linalg.norm(np.diff(normals, axis=-2), axis=-1)
    return np.any((np.minimum(length[..., :-1], length[..., 1:]) > floor) & (chords > NORMAL_CHORD), axis=-1)


def _simpson(f, tol, turns, segments):
    """∫_{-1}^{1} of the integrands of ``segments`` (k,) by adaptive Simpson from the panels [-1, 0] and [0, 1],
    each to its tolerance ``tol`` (k,): (k, 3).  ``f(segments, x)`` is the integrand of segments[i] at x[i];
    ``turns(segments, a, b)`` whether the normal turns across panel [a[i], b[i]] of segments[i], where a panel counts
    at least its width times its largest value as its error.  The panels of one depth are taken at once."""
    k = np.arange(len(segments))
    f5 = f(np.repeat(segments, 5), np.tile([-1.0, -0.5, 0.0, 0.5, 1.0], len(k))).reshape(len(k), 5, -1)
    which, a, b = np.repeat(k, 2), np.tile([-1.0, 0.0], len(k)), np.tile([0.0, 1.0], len(k))
    fa, fm, fb = (f5[:, [i, i + 2]].reshape(2 * len(k), -1) for i in (0, 1, 2))  # panels' ends and midpoints
    tol, total, depth = np.repeat(tol / 2, 2), np.zeros((len(k), f5.shape[2])), 1
    while len(which):
        m = (a + b) / 2
        flm, fmr = np.split(f(np.tile(segments[which], 2), np.concatenate([(a + m) / 2, (m + b) / 2])), 2)
        s1 = (b - a)[:, None] / 6 * (fa + 4 * fm + fb)
        s2 = (b - a)[:, None] / 12 * (fa + 4 * flm + 2 * fm + 4 * fmr + fb)
        err = np.abs(s2 - s1).max(axis=1)
        big = (b - a) * np.abs(np.stack([fa, flm, fm, fmr, fb])).max(axis=(0, 2))
        err = np.where(turns(segments[which], a, b), np.maximum(err, big), err)
        done = (err <= 15 * tol) | (depth >= SIMPSON_DEPTH)
        np.add.at(total, which[done], (s2 + (s2 - s1) / 15)[done])
        go = ~done  # the rest halve: left halves, then right halves
        which, tol = np.tile(which[go], 2), np.tile(tol[go] / 2, 2)
        a, b = np.concatenate([a[go], m[go]]), np.concatenate([m[go], b[go]])
        fa, fm, fb = (np.concatenate(pair) for pair in ((fa[go], fm[go]), (flm[go], fmr[go]), (fm[go], fb[go])))
        depth += 1
    return total


def classified_reference(wv, camera, transfer_function, lights=None, shading=True,
                         tracer: RayTracer | None = None, detail=0, clip=None) -> np.ndarray:
    """(H, W, 4) float64 image of a scalar model through ``transfer_function`` (post-classification), by brute
    force: no skipping, no early termination, no adaptivity (docs/raytracing.md §10), the scalar clamped to the
    input's range where the model knows it (``np.clip``, and cuts where it meets the range's ends), each ray
    integrated over the data's bounds only: the box of its outermost voxel centres in world units (a Haar model's
    voxels, and an axis of one voxel, whole).

    On each fine knot segment the scalar and its gradient are polynomials, fitted exactly from the model at ten
    Chebyshev points, sixteen for order 6 (:meth:`WaveletVolume.evaluate` / ``gradient``, or the B-spline
    backend's content-clamped coefficients); the segment is cut at every real root of ``s - v`` for each point
    value v (NumPy's companion-matrix roots), and where shading, at every real root of ``grad s . L`` for each
    light L and halfway vector (the normal flips there); on each piece the opacity ``np.interp(s)`` is a
    polynomial, fitted and integrated exactly, and the emission integral is composite Gauss-Legendre (8 x 8
    nodes).  ``tracer`` supplies the window of an "auto" transfer function and the gradient floor
    the kernel uses; ``detail``: the model without its details of levels 1 .. detail, as the B-spline field
    holds it (docs/raytracing.md §8); ``clip`` as :func:`raytrace_reference`'s.
    """
    tr = tracer or RayTracer(wv)
    view = camera.view(wv)
    H, W = view.size
    phong = (shading if isinstance(shading, Phong) else Phong()) if shading else None
    if tr.orders[0] == 1:
        phong = None
    light_dirs = light_directions(lights, view.n)
    values = tr.scalar.stored(transfer_function).data_points()
    least, most = tr.scalar.value_range or (-np.inf, np.inf)  # the classification sees the field clamped to the input's
    colour, opacity = transfer_function.points[:, 1:4], transfer_function.extinction(wv.spacing)
    scale, offset = world_to_fine_affine(tr.orders[0], wv.shape, wv.spacing, wv.origin)
    n = max(10, 3 * tr.orders[0] - 2)  # degree 3 (j - 1) at most on a knot segment
    cheb = np.cos(np.pi * (np.arange(n) + 0.5) / n)
    to_series = np.linalg.inv(chebyshev.chebvander(cheb, n - 1))
    gauss, gauss_w = np.polynomial.legendre.leggauss(8)
    evaluate = _content_field(wv, detail) if wv.content_mask is not None or detail else _model_field(wv)
    out = np.zeros((H, W, 4))
    floor = tr.scalar.classify(transfer_function, tr.cc, np.float64).grad_floor  # the kernel's flat gradients
    # the data's bounds: its outermost voxel centres in world units (Haar's voxels and an axis of one voxel whole)
    extent = np.array(wv.shape[::-1], float) - 1
    extent[(extent == 0) | (tr.orders[0] == 1)] += 1
    data = [np.asarray(wv.origin) + sign * extent / 2 * np.array(wv.spacing[::-1]) for sign in (-1, 1)]
    for r, c in np.ndindex(H, W):
        p, w = _ray(view, r, c)
        x0, d = p * scale + offset, w * scale
        t0, t1 = _cut(p, w, *_clip(p, w, data, view.perspective), clip)
        if not t1 > t0:
            continue
        directions = [*light_dirs, *((light - w) / np.linalg.norm(light - w) for light in light_dirs)] \
            if phong is not None and phong.specular else light_dirs
        knots = _knots(x0, d, t0, t1, 1.0)
        lo, hi = knots[:-1][knots[1:] > knots[:-1]], knots[1:][knots[1:] > knots[:-1]]
        mid, rad = (lo + hi) / 2, (hi - lo) / 2
        points = p + (mid[:, None] + rad[:, None] * cheb).reshape(-1, 1) * w
        s_series = np.einsum("mk,sk->sm", to_series, evaluate(points, False)[:, 0].reshape(len(mid), n))
        g_series = np.einsum("mk,skc->smc", to_series, evaluate(points, True)[:, 0].reshape(len(mid), n, 3)) \
            if phong else None
        T, colour_sum = 1.0, np.zeros(3)
        for k in range(len(mid)):
            cuts = [-1.0, 1.0]
            polys = [s_series[k] - v * (np.arange(n) == 0) for v in (*values, least, most)
                     if np.isfinite(v)]
            if phong is not None:  # where the normal flips against a light or halfway vector, n . L jumps or kinks
                polys += [g_series[k] @ d for d in directions]
            for poly in polys:
                roots = chebyshev.chebroots(poly)
                cuts += [x.real for x in roots if abs(x.imag) < 1e-6 and -1 < x.real < 1]
            cuts = np.unique(cuts)
            for a, b in zip(cuts[:-1], cuts[1:]):
                # alpha(s(xi)) on the piece: a polynomial in tau = (2 xi - a - b) / (b - a), interpolated at the
                # piece's Chebyshev points and integrated: int_a^xi alpha = (b - a) / 2 int_{-1}^tau
                xa = (a + b) / 2 + (b - a) / 2 * cheb
                alpha_series = to_series @ np.interp(np.clip(chebyshev.chebval(xa, s_series[k]), least, most), values,
                                                     opacity)
                if not np.any(alpha_series):
                    continue
                antiderivative = chebyshev.chebint(alpha_series, lbnd=-1) * (b - a) / 2

                def depth_to(xi, antiderivative=antiderivative, a=a, b=b):
                    return chebyshev.chebval((2 * xi - a - b) / (b - a), antiderivative)
                edges = np.linspace(a, b, 9)
                xs = ((edges[:-1] + edges[1:])[:, None] / 2 + np.diff(edges)[:, None] / 2 * gauss).ravel()
                s = np.clip(chebyshev.chebval(xs, s_series[k]), least, most)
                alpha = np.interp(s, values, opacity)
                q = np.stack([np.interp(s, values, colour[:, i]) for i in range(3)], axis=1) * alpha[:, None]
                if phong is not None:
                    middle = chebyshev.chebval((a + b) / 2, s_series[k])
                    i = np.searchsorted(values, middle, side="right")
                    slope = opacity[i] - opacity[i - 1] if 0 < i < len(values) and least < middle < most else 0.0
                    grads = chebyshev.chebval(xs, g_series[k]).T * (-1.0 if slope < 0 else 1.0)
                    q = np.array([_shade(qi, ai, gi, phong, light_dirs, w, floor)
                                  for qi, ai, gi in zip(q, alpha, grads)])
                weights = np.tile(gauss_w, 8) * (b - a) / 16
                emitted = np.einsum("n,nc->c", weights * np.exp(-rad[k] * depth_to(xs)), q)
                colour_sum += T * rad[k] * emitted
                T *= np.exp(-rad[k] * depth_to(b))
        out[r, c] = np.append(colour_sum, 1.0 - T)
    return out
