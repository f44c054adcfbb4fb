"""NumPy float64 reference of the ray tracer's quadrature (``cl/raytrace/raytrace.cl``), for tests.

The same algorithm, written independently of the kernel: the field comes from
:meth:`WaveletVolume.evaluate` / :meth:`~WaveletVolume.gradient` (closed-form wavelet
bases) instead of the device's fine B-spline grids; segments are the knot planes of
the lattice; alpha's exact Chebyshev series gives ``A``; ``∫ q e^{-A}`` comes from
recursive adaptive Simpson with two initial panels and the normal's resolution test (docs/raytracing.md §2);
early termination and the skipping of nearly empty blocks as in the kernel.  Slow (Python per segment): tiny
volumes and images only.
"""

from __future__ import annotations

import numpy as np
from numpy.polynomial import chebyshev

from ..device.constants import BLOCK, SUPER
from ..model.geometry import world_to_fine, world_to_fine_affine
from ..model.transform import Band, band_sum, synthesize
from .lod import occupancy
from .quadrature import sample_points
from .tracer import SIMPSON_DEPTH, Phong, RayTracer, light_direction


def raytrace_reference(wv, camera, tolerance=1e-3, lights=None, shading=True, absorption=True,
                       tracer: RayTracer | None = None) -> np.ndarray:
    """(H, W, 4) float64 image as :func:`clwave.raytrace` computes it, or (H, W, C) line integrals.

    ``tracer`` supplies the clip box, occupancy lattice and emission bound the kernel used.
    """
    tr = tracer or RayTracer(wv)
    view = camera.view(wv)
    H, W = view.size
    orders = tr.orders
    h = 0.5 if len({o % 2 for o in orders}) > 1 else 1.0
    phong = (shading if isinstance(shading, Phong) else Phong()) if shading else None
    if tr.orders[tr.alpha_group] == 1 or not absorption:
        phong = None
    light_dirs = [view.n] if lights is None else [light_direction(*lt) for lt in lights]
    gain = (phong.ambient + (phong.diffuse + phong.specular) * len(light_dirs)) if phong else 1.0
    regions = _Regions(tr.block_bound.get(), tr.occ_origin, tr.super_bound_host, tr.super_origin,
                       tr.coarse_bound(tolerance))
    scale, offset = world_to_fine_affine(orders[0], wv.shape, wv.spacing, wv.origin)
    # the kernel's points (the field is the same polynomial), a hair inside the segment's ends: there a Haar channel
    # takes its value from inside the segment, as the kernel's one piece per segment does (docs/raytracing.md §3)
    xi = sample_points(3 * (max(orders) - 1)) * (1.0 - 2.0 ** -32)
    n_samples = len(xi)
    out = np.zeros((H, W, 4 if absorption else wv.channels))
    rays = []
    for r, c in np.ndindex(H, W):
        p, w = _ray(view, r, c)
        t0, t1 = _clip(p * scale + offset, w * scale, tr.box, view.perspective)
        if t1 > t0:
            knots = _knots(p * scale + offset, w * scale, t0, t1, h)
            lo, hi = knots[:-1][knots[1:] > knots[:-1]], knots[1:][knots[1:] > knots[:-1]]
            rays.append((r, c, w, p * scale + offset, (lo + hi) / 2, (hi - lo) / 2, t0, t1,
                         p + ((lo + hi)[:, None] / 2 + (hi - lo)[:, None] / 2 * xi).reshape(-1, 1) * w))
    if not rays:
        return out
    points = np.concatenate([ray[-1] for ray in rays])  # one evaluation for every sample of every ray
    evaluate = _content_field(wv) if tr.field == "bspline" and wv.content_mask is not None else _model_field(wv)
    fields = np.split(evaluate(points, False), np.cumsum([len(ray[-1]) for ray in rays])[:-1])
    grads = np.split(evaluate(points, True)[:, 3, :], len(fields) and np.cumsum([len(f) for f in fields])[:-1]) \
        if phong else [None] * len(rays)
    for (r, c, w, x0, mid, rad, t0, t1, _), field, grad in zip(rays, fields, grads):
        field = field.reshape(len(mid), n_samples, -1)
        grad = None if grad is None else grad.reshape(len(mid), n_samples, 3)
        empty = ~_reached(tr, x0 + mid[:, None] * (w * scale))  # segments no content reaches: empty
        field[empty] = 0.0
        if grad is not None:
            grad[empty] = 0.0
        blocks = _BlockSkip(regions, x0, w * scale, t0, t1, absorption, tolerance, gain)
        if not absorption:
            keep = [s for s in range(len(mid)) if not blocks.skip(mid[s] - rad[s], mid[s] + rad[s], 1.0)]
            out[r, c] = np.einsum("s,sc->c", rad[keep], _integral(_fit(field[keep], xi)))
            continue
        field[..., 3] = np.maximum(field[..., 3], 0.0)  # alpha clamped at the samples, q where it is used
        out[r, c] = _emission_absorption(field, grad, xi, mid, rad, t1 - t0, tolerance, gain,
                                         phong, light_dirs, w, blocks, tr.grad_floor())
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


def _model_field(wv):
    """The field from the closed-form wavelet bases: ``f(points, derivative)``."""
    return lambda points, derivative: wv.gradient(points) if derivative else wv.evaluate(points)


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
        parts.append((g, coeffs, 2.0 ** level * np.array(start, float)))

    def field(points, derivative):
        out = np.zeros((len(points), wv.channels, 3) if derivative else (len(points), wv.channels))
        for g, coeffs, start in parts:
            fine = world_to_fine(points, g.wavelet.order, wv.shape, wv.spacing, wv.origin) - start
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


def _knots(x0, d, t0, t1, h):
    ts = [np.array([t0, t1])]
    for a in range(3):
        if d[a] != 0:
            ends = sorted([(x0[a] + t0 * d[a]) / h, (x0[a] + t1 * d[a]) / h])
            planes = np.arange(np.floor(ends[0]), np.ceil(ends[1]) + 1) * h
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


def _emission_absorption(field, grad, xi, mid, rad, total, tol, gain, phong, lights, w, blocks, floor):
    series = _fit(field, xi)
    grad_series = _fit(grad, xi) if grad is not None else None
    T, color = 1.0, np.zeros(3)
    shade_budget = tol * 3 / 8  # when shading: three quarters of the quadrature's half
    quadrature_share = tol / 8 if phong is not None else tol / 2
    quarters = -1.0 + np.arange(9) / 4.0
    for s in range(len(rad)):
        if blocks.skip(mid[s] - rad[s], mid[s] + rad[s], T):
            continue
        A = chebyshev.chebint(series[s, :, 3], lbnd=-1)
        if phong is not None:  # the midpoint of the shading range, when its error fits the shading budget
            unshaded = np.maximum(chebyshev.chebval(quarters, series[s]).T, 0.0) \
                * np.exp(-rad[s] * chebyshev.chebval(quarters, A))[:, None]  # (9, 4): q_RGB, alpha
            s4 = (unshaded[0] + 4 * unshaded[1:8:2].sum(0) + 2 * unshaded[2:8:2].sum(0) + unshaded[8]) / 12
            s2 = (unshaded[0] + 4 * unshaded[2] + 2 * unshaded[4] + 4 * unshaded[6] + unshaded[8]) / 6
            ds, n = np.abs(s4 - s2), len(lights)
            diffuse_mid, specular_mid = phong.ambient + phong.diffuse * n / 2, phong.specular * n / 2
            err = (phong.diffuse * n / 2 * (s4[:3] + ds[:3]) + specular_mid * (s4[3] + ds[3])
                   + diffuse_mid * ds[:3] + specular_mid * ds[3])
            cost = T * rad[s] * err.max()
            if cost <= shade_budget:
                shade_budget -= cost
                color += T * rad[s] * (diffuse_mid * s4[:3] + specular_mid * s4[3])
                T, done = _passed(T, rad[s], A, blocks, mid[s], gain, tol)
                if done:
                    break
                continue

        def integrand(x, s=s, A=A):
            f = chebyshev.chebval(x, series[s])
            q = np.maximum(f[:3], 0.0)
            if phong is not None:
                q = _shade(q, max(f[3], 0.0), chebyshev.chebval(x, grad_series[s]), phong, lights, w, floor)
            return q * np.exp(-rad[s] * chebyshev.chebval(x, A))

        def turns(a, b, s=s):
            return phong is not None and _normal_turns(chebyshev.chebval(np.linspace(a, b, 5), grad_series[s]).T, floor)

        seg_tol = quadrature_share * (2 * rad[s]) / total / T
        color += T * rad[s] * _simpson(integrand, seg_tol / rad[s], turns)
        T, done = _passed(T, rad[s], A, blocks, mid[s], gain, tol)
        if done:
            break
    return np.append(color, 1.0 - T)


def _passed(T, rad, A, blocks, mid, gain, tol):
    """T past the segment, and whether the ray stops there: what is left can change no output by tol/4."""
    T *= np.exp(-rad * chebyshev.chebval(1.0, A))
    left = blocks.passed(mid - rad, mid + rad)
    return T, T * max(min(1.0, left), gain * left) <= tol / 4


def _shade(q, alpha, grad, phong, lights, w, floor):
    """Phong's eq. 4 with the outward normal -grad/|grad| (world gradient of alpha); unlit at |grad| <= floor."""
    length = np.linalg.norm(grad)
    diffuse = specular = 0.0
    if length > floor:
        n = -grad / length
        for light in lights:
            halfway = (light - w) / np.linalg.norm(light - w)
            diffuse += max(n @ light, 0.0)
            specular += max(n @ halfway, 0.0) ** phong.shininess
    return q * (phong.ambient + phong.diffuse * diffuse) + phong.specular * alpha * specular


NORMAL_CHORD = 0.125  # the kernel's (cl/raytrace/quadrature.h)


def _normal_turns(grads, floor) -> bool:
    """Whether the normal -grad/|grad| moves by more than NORMAL_CHORD between neighbouring rows of ``grads``
    (world gradients at a panel's points) where neither is flat (docs/raytracing.md §2)."""
    length = np.linalg.norm(grads, axis=1)
    normals = grads / np.maximum(length, np.finfo(float).tiny)[:, None]
    chords = np.linalg.norm(np.diff(normals, axis=0), axis=1)
    return bool(np.any((np.minimum(length[:-1], length[1:]) > floor) & (chords > NORMAL_CHORD)))


def _simpson(f, tol, turns):
    """∫_{-1}^{1} f by recursive adaptive Simpson from the panels [-1, 0] and [0, 1]; a panel across which the
    normal ``turns(a, b)`` counts at least its width times its largest value as its error."""
    def panel(a, b, fa, fm, fb, tol, depth):
        m = (a + b) / 2
        flm, fmr = f((a + m) / 2), f((m + b) / 2)
        s1 = (b - a) / 6 * (fa + 4 * fm + fb)
        s2 = (b - a) / 12 * (fa + 4 * flm + 2 * fm + 4 * fmr + fb)
        err = np.max(np.abs(s2 - s1))
        if turns(a, b):
            err = max(err, (b - a) * np.max(np.abs([fa, flm, fm, fmr, fb])))
        if err <= 15 * tol or depth >= SIMPSON_DEPTH:
            return s2 + (s2 - s1) / 15
        return panel(a, m, fa, flm, fm, tol / 2, depth + 1) + panel(m, b, fm, fmr, fb, tol / 2, depth + 1)

    f0, f1, f2, f3, f4 = (f(x) for x in (-1.0, -0.5, 0.0, 0.5, 1.0))
    return panel(-1.0, 0.0, f0, f1, f2, tol / 2, 1) + panel(0.0, 1.0, f2, f3, f4, tol / 2, 1)


def classified_reference(wv, camera, transfer_function, lights=None, shading=True,
                         tracer: RayTracer | None = None, detail=0) -> np.ndarray:
    """(H, W, 4) float64 image of a scalar model through ``transfer_function`` (post-classification), by brute
    force: no skipping, no early termination, no adaptivity (docs/raytracing.md §10).

    On each fine knot segment the scalar and its gradient are polynomials, fitted exactly from the model at ten
    Chebyshev points, sixteen for order 6 (:meth:`WaveletVolume.evaluate` / ``gradient``, or the B-spline
    backend's content-clamped coefficients); the segment is cut at every real root of ``s - v`` for each point
    value v (NumPy's companion-matrix roots), and where shading, at every real root of ``grad s . L`` for each
    light L and halfway vector (the normal flips there); on each piece the opacity ``np.interp(s)`` is a
    polynomial, fitted and integrated exactly, and the emission integral is composite Gauss-Legendre (8 x 8
    nodes).  ``tracer`` supplies the clip box, the window of an "auto" transfer function and the gradient floor
    the kernel uses; ``detail``: the model without its details of levels 1 .. detail, as the B-spline field
    holds it (docs/raytracing.md §8).
    """
    tr = tracer or RayTracer(wv)
    view = camera.view(wv)
    H, W = view.size
    phong = (shading if isinstance(shading, Phong) else Phong()) if shading else None
    if tr.orders[0] == 1:
        phong = None
    light_dirs = [view.n] if lights is None else [light_direction(*lt) for lt in lights]
    values = transfer_function.data_points(tr.scalar.window(transfer_function))
    colour, opacity = transfer_function.points[:, 1:4], transfer_function.points[:, 4]
    scale, offset = world_to_fine_affine(tr.orders[0], wv.shape, wv.spacing, wv.origin)
    n = max(10, 3 * tr.orders[0] - 2)  # degree 3 (j - 1) at most on a knot segment
    cheb = np.cos(np.pi * (np.arange(n) + 0.5) / n)
    to_series = np.linalg.inv(chebyshev.chebvander(cheb, n - 1))
    gauss, gauss_w = np.polynomial.legendre.leggauss(8)
    evaluate = _content_field(wv, detail) if wv.content_mask is not None or detail else _model_field(wv)
    out = np.zeros((H, W, 4))
    floor = tr.scalar.classify(transfer_function, tr.cc, np.float64).grad_floor  # the kernel's flat gradients
    for r, c in np.ndindex(H, W):
        p, w = _ray(view, r, c)
        x0, d = p * scale + offset, w * scale
        t0, t1 = _clip(x0, d, tr.box, view.perspective)
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
            polys = [s_series[k] - v * (np.arange(n) == 0) for v in values]
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
                alpha_series = to_series @ np.interp(chebyshev.chebval(xa, s_series[k]), values, opacity)
                if not np.any(alpha_series):
                    continue
                antiderivative = chebyshev.chebint(alpha_series, lbnd=-1) * (b - a) / 2

                def depth_to(xi, antiderivative=antiderivative, a=a, b=b):
                    return chebyshev.chebval((2 * xi - a - b) / (b - a), antiderivative)
                edges = np.linspace(a, b, 9)
                xs = ((edges[:-1] + edges[1:])[:, None] / 2 + np.diff(edges)[:, None] / 2 * gauss).ravel()
                s = chebyshev.chebval(xs, s_series[k])
                alpha = np.interp(s, values, opacity)
                q = np.stack([np.interp(s, values, colour[:, i]) for i in range(3)], axis=1) * alpha[:, None]
                if phong is not None:
                    i = np.searchsorted(values, chebyshev.chebval((a + b) / 2, s_series[k]), side="right")
                    slope = opacity[i] - opacity[i - 1] if 0 < i < len(values) else 0.0  # normals: alpha falls
                    grads = chebyshev.chebval(xs, g_series[k]).T * (-1.0 if slope < 0 else 1.0)
                    q = np.array([_shade(qi, ai, gi, phong, light_dirs, w, floor)
                                  for qi, ai, gi in zip(q, alpha, grads)])
                weights = np.tile(gauss_w, 8) * (b - a) / 16
                emitted = np.einsum("n,nc->c", weights * np.exp(-rad[k] * depth_to(xs)), q)
                colour_sum += T * rad[k] * emitted
                T *= np.exp(-rad[k] * depth_to(b))
        out[r, c] = np.append(colour_sum, 1.0 - T)
    return out
