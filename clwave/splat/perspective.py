"""Perspective (cone-beam) splatting: one view's footprints at a grid of ray slopes and the tables of
``cl/splat/cone.cl`` (docs/splatting.md §8).

A pixel's ray of slopes ``s = (s_u, s_v)`` meets the plane through a splat's centre X, parallel to the
detector, at ``X + w`` with ``w = z_c (s - s_c)`` (z_c the centre's depth, s_c its slopes): exactly, with
no approximation.  Its integral over the basis function is ``sqrt(1 + |s|^2) G_s(w)`` with the sheared
footprint ``G_s(w) = ∫ B(X + w + t (n - s_u u - s_v v)) dt``, whose spectrum is the slice of the 3-D one
along ``u + s_u n`` and ``v + s_v n`` (:func:`sheared_footprints`).  G_s depends on s smoothly: it is
sampled at nodes :data:`SLOPE_STEP` apart (closer for voxels deep along the view, :func:`slope_steps`) covering
every pixel's slope, and each pixel interpolates between the four around its own.
"""

from __future__ import annotations

import time
from dataclasses import asdict
from math import ceil

import numpy as np
import scipy.fft

from ..device.constants import TILE
from ..errors import CommandWords, DeviceMemoryError, InputError
from ..model.bspline import wavelet_for
from ..model.camera import View
from ..model.conebeam import ConeBeam
from ..model.geometry import check_key, fine_to_world, spacing_xyz, support_centres, support_extent
from ..threads import cores, thread_map
from .cone_budget import refined_bands
from .cone_cells import idle_pool, pack_nodes, slope_cells
from .spatial import exact_samples
from .spectral import SPECTRUM_BLOCK, WORK_ROOM, device_spectra, fft_texture, slice_plan
from .tables import MAX_LEVELS, default_omega_s, texels_per_pixel
from .textures import (DEFAULT_OMEGA_MIN, FILTER_BELOW, Texture, _axis_points, check_texels, _axis_sampling, _centred,
                       _fast_even, filter_growth, pixel_filter)

#: Spacing of the slope grid (docs/splatting.md §8): bilinear interpolation between nodes errs by at most
#: ``SLOPE_STEP^2 / 8 (|d2G/ds_u2| + |d2G/ds_v2|)``; measured, about 1.1e-3 of the peak of a cubic
#: phi-phi-phi footprint at 0.1 (the error of each footprint scales with the square of the step)
SLOPE_STEP = 0.1
#: Smooth footprints (order >= 3) are stored as quasi-interpolants (:func:`quasi_interpolant`), whose bilinear reads
#: err by half the bound of the samples' (in slope, above, and in texels): cubic ones take a texel floor this much
#: coarser, which keeps the texels' share of the bound and halves the slopes' (docs/splatting.md §8; quintic images
#: came out less accurate with it, so they keep theirs)
QUASI_GAIN = np.sqrt(2.0)
TEXTURE_TOL = 1e-4  # cubic footprints trimmed as orthographic ones (clwave.splat.tables.TEXTURE_TOL)
FOOTPRINT_CACHE = 2  # views' texture tables a renderer keeps for poses that share a direction (ConeTables)
#: the most host memory of a view's slope-cell bounds (``cell_peaks``, :func:`check_slope_grid`): 64 x 64 cells for the
#: 8 textures of one level, 49 x 49 for three levels' 22; rays up to 68-72 degrees off the axis of a square cone
CELL_PEAKS_BYTES = 1 << 30
SPECTRA_BATCH_BYTES = 256 << 20  # the footprint spectra of a view go to the device in launches of at most this
#: the host tables of a perspective view, uploaded by name (cl/splat/cone.cl)
CONE_TABLES = ("band_tex", "band_world", "band_step", "tex_box", "tex_layer", "layers", "layer_slope", "cone",
               "tex_int", "tex_map", "texels")


def slope_grid(views, most=SLOPE_STEP) -> tuple:
    """``(lo, step, count)``, each (u, v): nodes ``lo + i step``, ``i < count``, at most ``most`` apart (a float or
    one along u and one along v; :func:`slope_steps`), covering the slopes of every pixel centre of ``views`` (two
    at least)."""
    ends = []  # the slopes of each view's first and last column and row, as View.slopes makes them: the extremes
    for view in views:
        (H, W), p, sigma = view.size, view.principal, view.slope
        ends.append(np.stack([p[0] + (np.array([0, W - 1]) + 0.5 - W / 2.0) * sigma[0],
                              p[1] + (H / 2.0 - np.array([0, H - 1]) - 0.5) * sigma[1]], axis=1))
    s = np.concatenate(ends)
    lo, hi = s.min(axis=0), s.max(axis=0)
    most = np.broadcast_to(np.asarray(most, float), 2)
    count = np.maximum(2, np.ceil((hi - lo) / most - 1e-9).astype(int) + 1)
    step = np.where(hi > lo, (hi - lo) / (count - 1), most)
    return lo, step, count


def slope_steps(n, d_xyz, scale) -> tuple:
    """``(step_u, step_v)``: the slope grid's spacing along u and v for a view along ``n`` of voxels ``d_xyz``
    (x y z) whose footprints vary on ``scale`` (:func:`texel_scale`) along the texture axes, ``SLOPE_STEP`` times
    ``c / depth`` where that is below 1, ``depth`` the voxels' spacing along ``n`` (``Σ|n_k| d_k / Σ|n_k|``).  A
    slope step ``Δ`` moves a ray across a support ``depth`` deep by ``Δ depth`` at its far ends, which the footprint
    feels on the scale ``c``: the slope interpolation's bound (docs/splatting.md §8 "Error") grows as
    ``(Δ depth / c)^2``, so these steps keep isotropic voxels' (where ``c = depth``) for any spacing."""
    n = np.abs(np.asarray(n, float))
    depth = float(n @ np.asarray(d_xyz, float) / n.sum())
    return tuple(SLOPE_STEP * min(1.0, c / depth) for c in scale)


def grid_nodes(lo, step, count) -> np.ndarray:
    """(K, 2): the slopes (u, v) of :func:`slope_grid`'s nodes, u fastest."""
    return np.stack(np.meshgrid(lo[0] + step[0] * np.arange(count[0]), lo[1] + step[1] * np.arange(count[1])),
                    -1).reshape(-1, 2)


def camera_words(camera) -> CommandWords:
    """The fixes a cone refusal names, in the API's words for ``camera``'s own class (a :class:`ConeBeam`'s
    detector and distances, a perspective :class:`Camera`'s field of view and distance, a resolved
    :class:`~clwave.model.camera.View`'s size and eye); the command line fills in its options instead
    (:class:`clwave.errors.CommandWords`)."""
    tracer = "clwave.RayTracer(wv, content_clamp=False).render(camera, absorption=False)"  # the same model
    if isinstance(camera, ConeBeam):
        return CommandWords("a smaller detector, ConeBeam size= or pixel=, or a longer dsd=", "a ConeBeam dso=", tracer)
    if isinstance(camera, View):
        return CommandWords("a smaller image or field of view", "an eye (source) farther away", tracer)
    return CommandWords("a smaller Camera fov=, or a less wide size=", "a Camera distance=", tracer)


def check_slope_grid(lo, step, count, textures: int, words: CommandWords) -> None:
    """Refuse (one line, before any work per node) a view whose :func:`slope_grid` ``(lo, step, count)`` is too wide
    for splatting: ``textures`` footprint textures need bounds over every range of slope cells (``cell_peaks``,
    ``T (k_u - 1)^2 (k_v - 1)^2`` doubles), which grow as tan^4 of the half-angle; past :data:`CELL_PEAKS_BYTES`
    the textures' texels are far beyond any device's memory too (docs/splatting.md §8).  ``words``: the camera's
    fixes (:func:`camera_words`)."""
    cells = np.asarray(count, np.int64) - 1
    need = 8 * max(int(textures), 1) * int(cells[0]) ** 2 * int(cells[1]) ** 2
    if need > CELL_PEAKS_BYTES:
        reach = np.degrees(np.arctan(np.max(np.abs([lo, lo + step * cells]))))
        template = (f"the cone is too wide for splatting: rays up to {reach:.1f} degrees off the axis, {count[0]} x "
                    f"{count[1]} ray-slope nodes (docs/splatting.md §8) whose footprint bounds alone need "
                    f"{need / 2**20:,.0f} MiB (at most {CELL_PEAKS_BYTES / 2**20:,.0f}); narrow the cone ({{narrow}}), "
                    "or ray-trace it ({tracer})")
        raise DeviceMemoryError(template.format_map(asdict(words)), cli=template, worded=True)


def quasi_interpolant(x: np.ndarray, axes=None) -> np.ndarray:
    """``x`` less 1/16 of its second differences along each of ``axes`` (default all) of three samples or more (at
    either end, the nearest one), in place: for a locally quadratic function, multilinear reads of these values err
    by at most ``Σ_a |f_aa| h_a^2 / 16`` (between -1/16 at the nodes and +1/16 at the cells' centres) where reads of
    the samples err by up to ``Σ_a |f_aa| h_a^2 / 8`` (docs/splatting.md §8)."""
    correction = np.zeros_like(x)
    for axis in range(x.ndim) if axes is None else axes:
        if x.shape[axis] >= 3:
            xa, ca = np.moveaxis(x, axis, 0), np.moveaxis(correction, axis, 0)
            d2 = xa[2:] + xa[:-2]
            d2 -= 2.0 * xa[1:-1]
            ca[1:-1] += d2
            ca[0] += d2[0]
            ca[-1] += d2[-1]
    correction *= 1.0 / 16.0
    x -= correction
    return x


def sheared_footprints(wavelet, spacing_zyx, n, u, v, bands, slopes, sampling="fft", tol=0.0, device=None,
                       max_texels=None, quasi=False, work=None, pixel=None) -> dict:
    """A :class:`~clwave.splat.textures.Texture` of each band whose ``data[node, iv, iu]`` holds its footprint
    at each of the (K, 2) ``slopes``: the line integrals of its basis
    function along ``n - s_u u - s_v v`` (per unit of depth) through the points ``a u + b v`` from its
    support centre.  ``bands`` maps ``(m, key)`` to the texel (world units; or a pair, along u and along v);
    ``"fft"`` slices the 3-D spectrum along ``u + s_u n``, ``v + s_v n`` (docs/splatting.md §8; on ``device``,
    every spectrum in one launch, as orthographic views do), ``"spatial"`` integrates exactly
    (:mod:`clwave.splat.spatial`).
    ``max_texels``: refuse (:class:`DeviceMemoryError`) textures that would hold more, before any is made.
    ``quasi``: each node's samples as their quasi-interpolant along rows and columns (:func:`quasi_interpolant`;
    on ``device``, in the spectra).  ``work``: a dict that keeps this call's arrays for the next to write over
    (fresh memory costs its first touch, docs/splatting.md §8): the device spectra's
    (:func:`~clwave.splat.spectral.device_spectra`) and the samples', so the textures returned are then views valid
    until the next call with it.
    ``pixel``: ``{(m, key): (p_u, p_v)}``, a detector pixel at the band's depth (world units) along u and v, or 0,
    by which its textures are box-filtered along that axis (:func:`~clwave.splat.textures.pixel_filter`; bands not in
    it keep their samples).
    A coarser band is made from the finest of its type in ``bands``: a scaled copy where its texels are that one's
    dilated too, else (``"fft"``, ``tol`` > 0) an FFT of the period that the box its trimming keeps needs
    (docs/splatting.md §8 "Periods from the trimmed box")."""
    wav = wavelet_for(wavelet)
    d_xyz = spacing_xyz(spacing_zyx)
    n, u, v = (np.asarray(x, float) for x in (n, u, v))
    slopes = np.asarray(slopes, float).reshape(-1, 2)
    grids, widths = {}, {}
    for (m, key), texel in bands.items():
        m, key = int(m), check_key(key)
        extent = support_extent(wav, key, m, d_xyz)
        # every node on one grid: the widest oblique projection of the support box over the nodes
        widths[(m, key)] = (max(float(np.abs(u + s * n) @ extent) for s in np.unique(slopes[:, 0])),
                            max(float(np.abs(v + s * n) @ extent) for s in np.unique(slopes[:, 1])))
        (nu, h_u, _), (nv, h_v, _) = (_axis_sampling(w, False, 0.0, 1.0, h)
                                      for w, h in zip(widths[(m, key)], np.broadcast_to(texel, 2)))
        grids[(m, key)] = (nu, h_u, nv, h_v)
    pixel = pixel or {}

    def grown(band, axis):  # the samples a pixel filter adds along axis 0 (u) or 1 (v)
        return filter_growth(pixel.get(band, (0.0, 0.0))[axis] / grids[band][1 + 2 * axis])

    check_texels(sum(4 * len(slopes) * (nu + 2 + grown(band, 0)) * (nv + 2 + grown(band, 1))
                     for band, (nu, _, nv, _) in grids.items()),  # the cells
                 max_texels, f"the footprints of this perspective view ({len(slopes)} ray slopes a band)",
                 "render fewer pixels, a narrower cone or a lower omega_s")
    data, profiles = {}, {}
    store = None if work is None else work.setdefault("samples", [np.zeros(0, np.float32), 0, 0])
    if store is not None:
        store[1:] = 0, 0  # (array, floats handed out, floats asked for)

    def empty(shape):  # a band's samples: in work's array after the bands' before it where it has room, else fresh
        size = int(np.prod(shape))
        if store is None:
            return np.empty(shape, np.float32)
        store[2] += size
        if store[1] + size > store[0].size:
            return np.empty(shape, np.float32)
        store[1] += size
        return store[0][store[1] - size:store[1]].reshape(shape)

    def sample(chosen):  # the samples of the bands ``chosen`` on their grids, and their row and column profiles
        jobs = [(band, k) for band in chosen for k in range(len(slopes))]
        spectra = {}
        if sampling == "fft" and device is not None:  # non-separable slices on the device, in few launches
            plans = {}
            for band, k in jobs:
                nu, h_u, nv, h_v = grids[band]
                su, sv = slopes[k]
                scale, axes = slice_plan(wav, band[1], band[0], d_xyz, u + su * n, v + sv * n, nu * h_u, nv * h_v)
                if any(alpha and beta for _, alpha, beta in axes):
                    plans[(band, k)] = (scale, axes, nu, nv)
            batch, held, launch = [], 0, 0
            for job, plan in list(plans.items()) + [(None, None)]:  # launches of at most SPECTRA_BATCH_BYTES
                size = 0 if plan is None else 8 * plan[3] * (plan[2] // 2 + 1 + SPECTRUM_BLOCK)
                if batch and (plan is None or held + size > SPECTRA_BATCH_BYTES):
                    spectra.update(zip(batch, device_spectra(device, wav.order, [plans[b] for b in batch], quasi,
                                                             None if work is None else work.setdefault(launch, {}))))
                    batch, held, launch = [], 0, launch + 1
                if plan is not None:
                    batch.append(job)
                    held += size

        def make(job):  # a node's samples and their largest magnitude along each row and each column
            band, k = job
            nu, h_u, nv, h_v = grids[band]
            su, sv = slopes[k]
            x = data[band][k]  # written in place
            if job in spectra:
                _centred(scipy.fft.irfft2(spectra[job], s=(nv, nu), workers=1, overwrite_x=True), np.float32, x)
            elif sampling == "fft":
                _centred(fft_texture(wav, band[1], band[0], d_xyz, u + su * n, v + sv * n, nu, nv, nu * h_u,
                                     nv * h_v, 1), np.float32, x)
            else:
                aa, bb = _axis_points(nu, h_u, False)[0], _axis_points(nv, h_v, False)[0]
                a, b = np.broadcast_arrays(aa[None, :], bb[:, None])
                x[...] = exact_samples(wav, band[1], band[0], d_xyz, n - su * u - sv * v, u, v, a.ravel().copy(),
                                       b.ravel().copy()).reshape(nv + 1, nu + 1)
            if quasi and job not in spectra:
                quasi_interpolant(x)
            magnitude = np.abs(x)
            return magnitude.max(axis=1), magnitude.max(axis=0)

        for band in chosen:
            nu, _, nv, _ = grids[band]
            data[band] = empty((len(slopes), nv + 1, nu + 1))
        found = thread_map(make, jobs) if len(jobs) > 1 and cores() > 1 else [make(job) for job in jobs]
        for band in chosen:
            profiles[band] = tuple(np.max([p[i] for (b, _), p in zip(jobs, found) if b == band], axis=0)
                                   for i in (0, 1))

    def crop(band, ru, rv):  # the samples within ru, rv texels of the centre
        nu, h_u, nv, h_v = grids[band]
        cu, cv = nu // 2, nv // 2
        data[band] = data[band][:, cv - rv:cv + rv + 1, cu - ru:cu + ru + 1]
        rows, cols = profiles[band]
        profiles[band] = (rows[cv - rv:cv + rv + 1], cols[cu - ru:cu + ru + 1])
        grids[band] = (2 * ru, h_u, 2 * rv, h_v)

    # the finest band of each key first: a coarser one's footprints are its own dilated by 2^(m - m0), with the
    # values 2^((m0 - m)/2) as large (docs/splatting.md §8)
    first = {}
    for band in sorted(grids):
        first.setdefault(band[1], band)
    sample(list(first.values()))
    rest, full, kept = [band for band in grids if band not in first.values()], dict(grids), {}
    for band in rest:
        sib, ratio = first[band[1]], 2.0 ** (band[0] - first[band[1]][0])
        nu, h_u, nv, h_v = grids[band]
        if np.allclose((h_u, h_v), ratio * np.array(grids[sib][1::2]), rtol=1e-12, atol=0.0):  # texels dilated too
            data[band] = np.multiply(data[sib], np.float32(ratio ** -0.5), out=empty(data[sib].shape))
            profiles[band] = tuple(p * ratio ** -0.5 for p in profiles[sib])
            grids[band] = (grids[sib][0], h_u, grids[sib][2], h_v)
        elif tol > 0 and sampling == "fft":  # the box its trimming keeps, known from the finest one's
            reach = ratio * (kept_radius(grids[sib], profiles[sib], tol) + grids[sib][1::2])
            kept[band] = np.minimum(np.ceil(reach / (h_u, h_v)).astype(int) + 1, (nu // 2, nv // 2)).tolist()
            # a period past the box by half the support: the periodic copies of the support miss the box
            nu, nv = (min(count, max(2 * r, _fast_even(ceil(r + w / (2.0 * h))))) for count, r, w, h in
                      zip((nu, nv), kept[band], widths[band], (h_u, h_v)))
            grids[band] = (nu, h_u, nv, h_v)
    sample([band for band in rest if band not in data])
    wider = []
    for band in kept:  # the box kept, and a check that the samples at its edges fall under tol
        crop(band, *kept[band])
        rows, cols = profiles[band]
        if max(rows[0], rows[-1], cols[0], cols[-1]) > tol * rows.max():
            wider.append(band)
    grids.update({band: full[band] for band in wider})  # past its prediction: the whole support after all
    sample(wider)
    out = {}
    for band, (nu, h_u, nv, h_v) in grids.items():
        (rows, cols), cu, cv, x = profiles[band], float(nu // 2), float(nv // 2), data[band]
        if tol > 0 and rows.max() > 0:  # the box of the samples above tol of the peak, over every node
            rows, cols = np.flatnonzero(rows > tol * rows.max()), np.flatnonzero(cols > tol * rows.max())
            x = x[:, rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1]
            cu, cv = cu - cols[0], cv - rows[0]
        p_u, p_v = pixel.get(band, (0.0, 0.0))
        if p_u:
            x, cu = pixel_filter(x, cu, p_u / h_u, axis=2)
        if p_v:
            x, cv = pixel_filter(x, cv, p_v / h_v, axis=1)
        out[band] = Texture(x, h_u, h_v, cu, cv, sampling, *band)
    if store is not None and store[2] > store[0].size:  # room for the next call, which then writes over it
        store[0] = np.empty(int(WORK_ROOM * store[2]), np.float32)
    return out


def kept_radius(grid, profiles, tol) -> np.ndarray:
    """``(r_u, r_v)``: how far (world units) from the centre of a texture on ``grid`` ``(nu, h_u, nv, h_v)`` its
    samples above ``tol`` of the peak reach, from their ``profiles`` (largest magnitude along each row, each
    column)."""
    nu, h_u, nv, h_v = grid
    rows, cols = profiles
    out = []
    for profile, count, h in ((cols, nu, h_u), (rows, nv, h_v)):
        above = np.flatnonzero(profile > tol * rows.max())
        out.append(0.0 if above.size == 0 else max(count // 2 - above[0], above[-1] - count // 2) * h)
    return np.array(out)


def band_texel(order: int, level: int, omega_s, pixel: float, d_xyz, scale) -> tuple:
    """``((texel_u, texel_v), omega)``: a band's texel along each texture axis (world units) and the texture band
    that set it (docs/splatting.md §8); ``scale``: the view's :func:`texel_scale`.

    Smooth footprints (order >= 3) are read at any magnification, so their texels follow the band alone, as
    in §1, ``pi c / max(omega / QUASI_GAIN, omega_least)`` (cubic; other orders ``omega``) with ``omega`` the paper's
    14 (doubled for order 6) or ``omega_s``, whatever the pixel, and ``c`` (``scale``) the spacing the footprint
    varies on along that axis (:data:`QUASI_GAIN`: they are stored as quasi-interpolants).
    Kinked footprints (orders 1, 2) keep the orthographic rule at the nearest pixel (``pixel``): a fraction of
    it where that pixel is at least about pi/28 voxel (two texels a pixel), so that bilinear reads place their kinks
    within a fraction of a pixel; at finer pixels a texel of pi/56 voxel (:func:`texels_per_pixel`), several
    pixels wide at a pixel of 0.01 voxel."""
    d_min = float(np.min(d_xyz))
    if order >= 3:
        omega = omega_s if omega_s is not None else default_omega_s(np.inf, d_min, order)
        band = max(omega / (QUASI_GAIN if order == 4 else 1.0), DEFAULT_OMEGA_MIN[order] / 2.0 ** level)
        return (np.pi * scale[0] / band, np.pi * scale[1] / band), omega
    omega = omega_s if omega_s is not None else default_omega_s(pixel, d_min, order)
    texel = pixel / texels_per_pixel(order, level, omega, pixel, d_min)
    return (texel, texel), omega


def texel_scale(axes_u, axes_v, d_xyz) -> tuple:
    """``(c_u, c_v)``: the spacing a footprint varies on along each sheared texture axis, over every slope node's
    axes ``u + s_u n`` (``axes_u``, (K, 3)) and ``v + s_v n`` (``axes_v``): at least d_min, more where every world
    axis that the texture axis crosses is coarser (:func:`axis_scale`; a CT's 2.5 mm slices seen from the side).
    The same for every band."""
    d_min = float(np.min(d_xyz))
    return (max(d_min, float(np.min(axis_scale(axes_u, axes_v, d_xyz)))),
            max(d_min, float(np.min(axis_scale(axes_v, axes_u, d_xyz)))))


def axis_scale(a, b, d_xyz):
    """``min_t max_k d_k |a_k + t b_k|``: the spectrum ``F(U a + V b)`` of a tensor-product footprint (§1:
    ``Π_k G(2^m d_k w_k)``) falls, at every V, at least as fast along U as an axis-aligned one of spacing this
    (its slowest factor's argument is at least ``U`` times it), so a texel along ``a`` may be ``pi`` times it
    over the band.  The minimum of this convex, piecewise linear function of t is at a kink: where a term
    vanishes or two are equal.  ``a``, ``b``: (3,), a float back, or (K, 3), one for each row."""
    a, b, d = (np.asarray(x, float) for x in (a, b, d_xyz))
    da, db = np.atleast_2d(d * a), np.atleast_2d(d * b)

    def kink(num, den):  # num / den, or 0 (a kink listed already) where den is 0
        return np.divide(num, den, out=np.zeros_like(num), where=den != 0.0)

    t = [np.zeros(len(da))] + [kink(-da[:, k], db[:, k]) for k in range(3)]
    t += [kink(sign * da[:, j] - da[:, i], db[:, i] - sign * db[:, j])
          for i in range(3) for j in range(3) for sign in (1.0, -1.0) if i != j]
    t = np.stack(t, axis=1)  # (K, kinks)
    out = np.min(np.max(np.abs(da[:, None, :] + t[:, :, None] * db[:, None, :]), axis=2), axis=1)
    return float(out[0]) if a.ndim == 1 else out


def depth_range(view, wv, extent_xyz) -> tuple:
    """The least and greatest depth (along -n from the eye) of the model's voxel box grown by a support box
    ``extent_xyz`` (world, x y z): no basis function of that size reaches nearer the eye."""
    half = np.array(wv.shape[::-1], float) * np.array(wv.spacing[::-1], float) / 2.0 + np.asarray(extent_xyz) / 2.0
    corners = np.array(np.meshgrid(*zip(np.asarray(wv.origin) - half, np.asarray(wv.origin) + half),
                                   indexing="ij")).reshape(3, -1).T
    depth = view.depth(corners)
    return float(np.min(depth)), float(np.max(depth))


def _too_near(view, wv, wav, d_xyz, level: int, drawn, words: CommandWords):
    """Refuse (one line) an eye behind which the level-``level`` basis functions reach (a splat's footprint
    integrates the whole line, docs/splatting.md §8), naming the fixes: the most levels whose functions stay in
    front (of any type), the distance that keeps those of every band ``drawn`` ((level, key)) in front, the ray
    tracer (``words``: the camera's, :func:`camera_words`)."""
    def near(m, keys=("aaa", "ddd")):  # the least depth a level-m function of these types reaches
        return depth_range(view, wv, np.max([support_extent(wav, key, m, d_xyz) for key in keys], axis=0))[0]

    fit = 0
    while fit + 1 < level and near(fit + 1) > 0:
        fit += 1
    distance = float(np.linalg.norm(view.eye - view.target)) - min(near(m, [key]) for m, key in drawn)
    why = (f"the eye (X-ray source) is inside the model or too near it for splatting: its level-{level} basis "
           "functions reach behind the eye; use ")
    fixes = f"{{distance}} above {distance:.4g}, or the ray tracer ({{tracer}})"
    raise InputError(why + (f"a model of at most {fit} level(s), " if fit else "") + fixes.format_map(asdict(words)),
                     cli=why + (f"--levels {fit} or fewer, " if fit else "") + fixes, worded=True)


class ConeTables:
    """The tables of one channel group for one perspective view (``cl/splat/cone.cl``), every layer
    (framebuffer) in one set, as :class:`clwave.splat.tables.ViewTables` for orthographic views."""

    names = CONE_TABLES

    def __init__(self, wv, group: int, layers, omega_s=None, sampling="auto", device=None, max_texels=None,
                 cache=None, work=None, words: CommandWords = None):
        """``cache``: a dict in which a renderer keeps the texture tables of its last views (at most
        :data:`FOOTPRINT_CACHE`), keyed by all they depend on (the view's direction and slope grid, the bands'
        texels and layers), so poses that differ by a translation (registration steps) share them; ``work``: a dict
        that keeps the footprint spectra's arrays for the next view (:func:`sheared_footprints`); ``words``: the
        fixes its refusals name, the camera's (:func:`camera_words`; by default a :class:`Camera`'s)."""
        words = words or camera_words(None)
        g = wv.groups[group]
        wav = g.wavelet
        if wav.order == 1:  # docs/splatting.md §8 "Error": Haar footprints' edges move with each ray's slope
            template = ("cone-beam splatting does not draw Haar wavelets within 1e-2 of the image maximum (their "
                        "footprints' edges move with each ray's slope, docs/splatting.md §8): ray-trace the view "
                        "({tracer}), exact for them, or use a smoother wavelet (linear, quadratic, cubic)")
            raise InputError(template.format_map(asdict(words)), cli=template, worded=True)
        if sampling == "cells":
            raise InputError("footprint sampling 'cells' is for orthographic views; perspective views take "
                             "'auto', 'fft' or 'spatial'")
        sampling = ("fft" if wav.order >= 3 else "spatial") if sampling == "auto" else sampling
        view0 = layers[0][0]
        d_xyz = np.array(wv.spacing[::-1], float)
        steps = slope_steps(view0.n, d_xyz, texel_scale(view0.u[None], view0.v[None], d_xyz))  # at the view's axis
        lo, step, count = slope_grid([view for view, _ in layers], steps)
        drawn = [(b.level, b.key) for b in g.bands if any(bands is None or (b.level, b.key) in bands
                                                          for _, bands in layers)]
        check_slope_grid(lo, step, count, len(drawn), words)
        nodes = grid_nodes(lo, step, count)
        self.cone = np.zeros((6, 4), np.float32)
        self.cone[0, :3], self.cone[1, :3], self.cone[2, :3], self.cone[3, :3] = view0.eye, view0.n, view0.u, view0.v
        self.cone[4] = (*view0.principal, *lo)
        self.cone[5] = (*(1.0 / step), *count)
        scale = texel_scale(view0.u + nodes[:, :1] * view0.n, view0.v + nodes[:, 1:] * view0.n, d_xyz)
        # each band in the first layer that draws it, with texels of 1/P of its nearest pixel
        texels, layer_of, pixel, self.omega_s = {}, {}, {}, None
        for li, (view, bands) in enumerate(layers):
            for b in g.bands:
                band = (b.level, b.key)
                if band in layer_of or (bands is not None and band not in bands):
                    continue
                near, far = depth_range(view, wv, support_extent(wav, b.key, b.level, d_xyz))
                if not near > 0:
                    _too_near(view, wv, wav, d_xyz, b.level, drawn, words)
                layer_of[band] = li
                # footprints under FILTER_BELOW of the nearest pixel, filtered by the pixel at the middle depth
                voxel, slope = 2.0 ** b.level * np.abs([view.u, view.v]) @ d_xyz, np.array(view.slope)
                p = np.where(voxel < FILTER_BELOW * slope * near, slope * (near + far) / 2.0, 0.0)
                if p.any():
                    pixel[band] = tuple(p.tolist())
                texels[band], omega = band_texel(wav.order, b.level, omega_s, min(view.slope) * near, d_xyz, scale)
                self.omega_s = self.omega_s or omega
        # bands whose images are large get closer slope nodes and finer texels (docs/splatting.md §8 "Refined bands")
        self.refined = refined_bands(wv, group, view0, texels, scale, step, steps)
        texels = {band: tuple(np.broadcast_to(h, 2) / self.refined[band][1]) for band, h in texels.items()}
        refine = {band: r for band, (r, _) in self.refined.items()}
        self.samplings = [sampling]
        self.band_tex = np.full(8 * MAX_LEVELS, -1, np.int32)
        self.band_world = np.zeros((8 * MAX_LEVELS, 4), np.float32)
        self.band_step = np.zeros((8 * MAX_LEVELS, 4), np.float32)
        self.layers = np.zeros((len(layers), 4), np.int32)  # (width, height, first tile, first pixel)
        self.layer_slope = np.zeros((len(layers), 4), np.float32)
        self.tiles = self.pixels = 0
        for li, (view, _) in enumerate(layers):
            H, W = view.size
            self.layers[li] = (W, H, self.tiles, self.pixels)
            self.layer_slope[li, :2] = view.slope
            self.tiles += -(-W // TILE) * -(-H // TILE)
            self.pixels += H * W
        for b in g.bands:
            if (b.level, b.key) in layer_of:  # world centre of coefficient k = 0 (docs/model.md §4) and its steps
                self.band_world[b.id, :3] = fine_to_world(
                    support_centres(wav, b.key, b.level, (0, 0, 0)), wav.order, wv.shape, wv.spacing, wv.origin)
                self.band_step[b.id, :3] = 2.0 ** b.level * d_xyz
        key = (group, sampling, max_texels, tuple(sorted(layer_of.items())), tuple(sorted(refine.items())),
               tuple(sorted(pixel.items())),
               tuple(sorted((band, tuple(np.broadcast_to(h, 2).tolist())) for band, h in texels.items())),
               *(np.asarray(x, np.float64).tobytes() for x in (view0.n, view0.u, view0.v, nodes)))
        start = time.perf_counter()
        if cache is not None and key in cache:
            packed = cache[key]
        else:
            try:
                textures = {}
                for r in sorted(set(refine.values())):  # each refinement's bands on its own nodes
                    chosen = {band: h for band, h in texels.items() if refine[band] == r}
                    textures.update(sheared_footprints(
                        wav, wv.spacing, view0.n, view0.u, view0.v, chosen,
                        grid_nodes(lo, step / r, (count - 1) * r + 1), sampling,
                        TEXTURE_TOL if wav.order == 4 else 0.0, device, max_texels, quasi=wav.order >= 3,
                        work=None if work is None else work.setdefault(r, {}),
                        pixel={band: p for band, p in pixel.items() if band in chosen}))
                spare = None  # the nodes' array of the view that leaves the cache, to write over
                while cache is not None and len(cache) >= FOOTPRINT_CACHE:
                    spare = cache.pop(next(iter(cache)))["nodes"]
                packed = pack_nodes(g, textures, layer_of, len(layers), count, max_texels, spare, refine)
            except DeviceMemoryError as err:  # the texel cap: the ray tracer draws any cone, thick voxels' too
                template = str(err).replace("{", "{{").replace("}", "}}") + ", or ray-trace it ({tracer})"
                raise DeviceMemoryError(template.format_map(asdict(words)), worded=True,
                                        cli=template.replace("omega_s", "--omega-s")) from None
            if cache is not None:
                cache[key] = packed
        if packed["texels"] is None:  # the slope cells on the device, quasi-interpolants along the slope nodes too
            packed["texels"], packed["cell_peaks"] = slope_cells(device, packed, count, wav.order >= 3,
                                                                 idle_pool(cache or {}, key, packed["pool_floats"]))
        for other, older in (cache or {}).items():  # only this view's pool stays on the device with the cache
            if other != key:
                older["texels"] = None
        self.footprint_seconds = time.perf_counter() - start
        self.band_tex[:] = packed["band_tex"]
        self.tex_box, self.tex_int, self.tex_map, self.tex_layer, self.texels, self.layer_textures, self.cell_peaks = (
            packed[name] for name in ("tex_box", "tex_int", "tex_map", "tex_layer", "texels", "layer_textures",
                                      "cell_peaks"))

    def splat_bounds(self, view, bbox, stex, values) -> np.ndarray:
        """(n, C): a bound of each image-layer splat's contribution to any of its pixels before the obliquity
        factor, ``|c|`` times its footprint's largest magnitude at the slope nodes of the cells its pixels read
        (a pixel's value is bilinear between them; docs/splatting.md §8 "Dropped splats").  ``bbox`` (n, 4)
        ``(x0, y0, x1, y1)`` in ``view``'s pixels (non-empty), ``stex`` their textures, ``values`` (n, C)."""
        lo, inv, count = self.cone[4, 2:], self.cone[5, :2], self.cone[5, 2:].astype(int)
        slopes = view.slopes()
        cu = np.clip(np.floor((slopes[0, :, 0] - lo[0]) * inv[0]), 0, count[0] - 2).astype(np.intp)  # per column
        cv = np.clip(np.floor((slopes[:, 0, 1] - lo[1]) * inv[1]), 0, count[1] - 2).astype(np.intp)  # per row
        (u0, u1), (v0, v1) = ((np.minimum(a, b), np.maximum(a, b))  # slopes are monotonic along rows and columns
                              for a, b in ((cu[bbox[:, 0]], cu[bbox[:, 2]]), (cv[bbox[:, 1]], cv[bbox[:, 3]])))
        return np.abs(values) * self.cell_peaks[stex, v0, v1, u0, u1][:, None]


def select_drops(bbox, bound, size, budget) -> tuple:
    """``(drop, most)``: a mask of the splats to drop, the longest run of them in order of increasing bound
    (relative to ``budget``, (C,); to within an eighth of an octave) whose bounds, summed over the splats covering
    any pixel of the (H, W) ``size``, stay within ``budget`` in every channel; and that sum's maximum over the
    pixels (C,).  ``bbox`` (n, 4) ``(x0, y0, x1, y1)``, ``bound`` (n, C)."""
    H, W = size
    budget = np.asarray(budget, float)
    # in order of increasing bound to within an eighth of an octave (a radix sort of small integers)
    ratio = np.max(bound / budget, axis=1)
    key = np.clip(np.floor(8.0 * np.log2(np.maximum(ratio, 2.0 ** -1000))), -8000, 8000).astype(np.int16)
    order = np.argsort(key, kind="stable")
    box, weight = bbox[order].astype(np.intp), bound[order]
    # each box as a 2-D difference array's four corners, integrated by cumulative sums
    corners = np.stack([box[:, 1] * (W + 1) + box[:, 0], box[:, 1] * (W + 1) + box[:, 2] + 1,
                        (box[:, 3] + 1) * (W + 1) + box[:, 0], (box[:, 3] + 1) * (W + 1) + box[:, 2] + 1], 1)
    signs = np.array([1.0, -1.0, -1.0, 1.0])

    def add(diff, a, b):  # the difference arrays of splats a..b added to those of every channel
        return diff + np.stack([np.bincount(corners[a:b].ravel(), (weight[a:b, c, None] * signs).ravel(),
                                            minlength=(H + 1) * (W + 1)) for c in range(len(budget))])

    def most(diff):
        return diff.reshape(-1, H + 1, W + 1).cumsum(1).cumsum(2).max(axis=(1, 2))

    lo, hi, fits = 0, len(order), np.zeros((len(budget), (H + 1) * (W + 1)))
    while lo < hi:  # the longest prefix that fits (the sums grow with the prefix); each try adds only its new splats
        mid = (lo + hi + 1) // 2
        trial = add(fits, lo, mid)
        if np.all(most(trial) <= budget):
            lo, fits = mid, trial
        else:
            hi = mid - 1
    drop = np.zeros(len(order), bool)
    drop[order[:lo]] = True
    return drop, most(fits)
