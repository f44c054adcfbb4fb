"""Footprint textures of the B-spline wavelet prototypes (paper §4, docs/splatting.md §1).

:func:`footprints` samples ``T_{m,key}(a, b)``, the X-ray of one basis function along the view
direction, for every band of a view: by projection slicing (``"fft"``, :mod:`clwave.splat.spectral`),
as exact line integrals (``"spatial"``, :mod:`clwave.splat.spatial`), or, for Haar along a world
axis, as its exact cells (``"cells"``).

Examples
--------
>>> from clwave.model.bspline import SplineWavelet
>>> from clwave.model.geometry import view_frame
>>> n, u, v = view_frame(30.0, 20.0)
>>> tex = footprints(SplineWavelet(4), (1.0, 1.0, 1.0), n, u, v, [(1, "aad")])[(1, "aad")]
>>> tex.sampling, tex.data.dtype, tex.data.shape == (tex.data.shape[0], 2 * tex.centre_u + 1)
('fft', dtype('float32'), True)
>>> abs(float(tex.data[:-1, :-1].sum()) * tex.h_u * tex.h_v) < 1e-6  # one period: ∫psi = 0
True
"""

from __future__ import annotations

from dataclasses import dataclass
from math import ceil, prod

import numpy as np
import scipy.fft

from ..device.memory import check_fits
from ..errors import DeviceMemoryError, InputError, finite_number
from ..threads import cores, thread_map
from ..model.bspline import wavelet_for
from ..model.geometry import check_key, footprint_vanishes, orthonormal_frame, spacing_xyz, support_extent
from .spatial import exact_samples
from .spectral import device_spectra, fft_texture, slice_plan

#: Default ``omega_min`` per B-spline order: the band, in prototype units, that keeps every
#: FFT footprint within 1e-3 of its level's phi-phi-phi peak at oblique and axis-aligned views
#: (worst case: an axis view, unit spacing, where the slice runs along the slowest-decaying
#: direction of the spectrum).  Measured worst errors / aaa peak, m = 0 and 1, unit and
#: (2, 1, 0.5) spacing: cubic 2.6e-2 at the paper's 14 (docs/splatting.md §1: 3.0e-2), 1.4e-3 at 32,
#: 1.06e-3 at 40, 8.3e-4 at 44, 6.0e-4 at 48; quadratic (C^1, slower) 1.5e-3 at 64, 7.3e-4 at
#: 72, 8.2e-4 at 80 (not monotone), 3.8e-4 at 96.  Oblique views are at float32 rounding
#: (~1e-7) for both.  Orders 1 and 2 take the exact spatial sampling by default, where the band
#: only sets the texel spacing, so they keep the paper's omega_s alone.  Quintic (C^4, its spectrum
#: falls like w^-6): 1.2e-3 at 16, 9.5e-5 at 24, 1.6e-5 at 32 (oblique 3.8e-4, 6.1e-7, 1.9e-7).
DEFAULT_OMEGA_MIN = {1: 0.0, 2: 0.0, 3: 96.0, 4: 48.0, 6: 24.0}
#: the largest footprint band omega_s (the defaults reach 100): at 1e4 one cubic band of level 0 is 38,590 samples a
#: side (6 GB of float32), past any view's texture cap, and 1e308 overflowed the sample count (an internal error)
OMEGA_S_MAX = 1e4

SAMPLINGS = ("auto", "fft", "spatial", "cells")

#: Footprints of a level whose voxels project narrower than this many pixels along an image axis are box-filtered
#: there by one pixel (EWA's pixel low-pass, Zwicker et al. 2001; docs/splatting.md §1 "Pixel filter"): point samples
#: of footprints under a pixel miss them or hit their peaks, so a needle or a small image of a big volume lost or
#: gained most of its mass.  A pixel's value is then the mean of the line integrals over its square, and the image's
#: sum times the pixel area the footprints' integral.  Levels of wider voxels (footprints of 2 to 7 voxels: about a
#: pixel or more) keep their point samples, and their images do not change (linear voxels of 0.43 pixel along u,
#: tests/test_splat.py's mixed views, would: pixel means there, against the tests' point samples).
FILTER_BELOW = 1.0 / 3.0


@dataclass
class Texture:
    """One sampled footprint ``T_{level,key}``.

    ``data[iv, iu] = T(a, b)`` at ``a = (iu - centre_u) h_u``, ``b = (iv - centre_v) h_v``
    (world units; rows run along v, columns along u).  A perspective view's textures hold one such
    per node of its slope grid, ``data[node, iv, iu]`` (:mod:`clwave.splat.perspective`).

    Attributes
    ----------
    data : (Nv, Nu) float32
    h_u, h_v : float
        World spacing of the samples along u and v.
    centre_u, centre_v : float
        Sample coordinates of the support centre (the basis function's projected centre).
    sampling : str
        ``"fft"``, ``"spatial"``, or ``"cells"``, ``"cells-u"``, ``"cells-v"`` (cells along
        both axes, u only, v only: there the samples are the 2 cell centres of the support,
        for nearest-sample lookup; see :attr:`cells`).
    level : int
    key : str
        Subband key in array-axis order (z, y, x).
    """

    data: np.ndarray
    h_u: float
    h_v: float
    centre_u: float
    centre_v: float
    sampling: str
    level: int
    key: str

    @property
    def shape(self) -> tuple:
        return self.data.shape

    @property
    def cells(self) -> tuple:
        """``(along u, along v)``: whether the samples of that axis are cells (nearest lookup)."""
        return self.sampling in ("cells", "cells-u"), self.sampling in ("cells", "cells-v")

    def coordinates(self) -> tuple:
        """World offsets ``(a, b)`` of the columns and rows from the support centre."""
        nv, nu = self.data.shape[-2:]
        return (np.arange(nu) - self.centre_u) * self.h_u, (np.arange(nv) - self.centre_v) * self.h_v

    @property
    def box(self) -> tuple:
        """``(a_min, a_max, b_min, b_max)``: the world box the samples cover."""
        a, b = self.coordinates()
        return float(a[0]), float(a[-1]), float(b[0]), float(b[-1])


def sample_count(order: int, m: int, omega_s: float = 14.0, width=None) -> int:
    """Paper eq. 33/36: ``N(m) = ceil(2^(m+1) omega_s / dw_0 + 1)``, ``dw_0 = 2 pi / width``.

    ``width`` defaults to the paper's ``sqrt(3) (2j - 1)`` (the diameter of the psi support
    cube).  At omega_s = 14 this reproduces Table I (with j = 1 for Haar; docs/errata.md):

    >>> [sample_count(4, m) for m in range(4)]
    [56, 110, 218, 434]
    """
    if width is None:
        width = np.sqrt(3.0) * (2 * order - 1)
    return int(ceil(2.0 ** (m + 1) * omega_s * width / (2.0 * np.pi) + 1.0))


def _fast_even(n: int) -> int:
    """Smallest even FFT-friendly length >= n."""
    n = scipy.fft.next_fast_len(max(int(n), 2), real=True)
    while n % 2:
        n = scipy.fft.next_fast_len(n + 1, real=True)
    return n


def cell_axes(wavelet, u, v) -> tuple:
    """``(along u, along v)``: where the ``"cells"`` lookup is exact, i.e. Haar and the image
    axis along a world axis (the footprint is piecewise constant along it, 2 cells).

    >>> from clwave.model.geometry import view_frame
    >>> n, u, v = view_frame(90.0, 0.0)
    >>> cell_axes("haar", u, v), cell_axes("linear", u, v), cell_axes("haar", *view_frame(0.0, 10.0)[1:])
    ((True, True), (False, False), (True, False))
    """
    haar = wavelet_for(wavelet).order == 1
    return tuple(bool(haar and np.max(np.abs(np.asarray(w, float))) > 1.0 - 1e-12) for w in (u, v))


# ----------------------------------------------------------------------------- textures
def _centred(t, dtype, out=None) -> np.ndarray:
    """FFT-order samples (sample 0 at a = b = 0) to the closed box, centre at ``(N//2, N//2)``
    (into ``out`` where given).

    Row and column N repeat row and column 0 (the period is the box width), so the box
    ``[-W/2, W/2]`` is closed on both sides.
    """
    nv, nu = t.shape
    hv, hu = nv // 2, nu // 2  # N even: N - N//2 == N//2
    out = np.empty((nv + 1, nu + 1), dtype) if out is None else out
    out[hv:nv, hu:nu] = t[:hv, :hu]
    out[hv:nv, :hu] = t[:hv, hu:]
    out[:hv, hu:nu] = t[hv:, :hu]
    out[:hv, :hu] = t[hv:, hu:]
    out[:nv, nu] = out[:nv, 0]
    out[nv] = out[0]
    return out


def _trim(data, centre_u, centre_v, tol):
    if tol <= 0:
        return data, centre_u, centre_v
    mask = np.abs(data) > tol * np.max(np.abs(data))
    if not mask.any():
        return data[:1, :1], 0.0, 0.0
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    r0, r1, c0, c1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
    return data[r0:r1, c0:c1], centre_u - c0, centre_v - r0


def filter_growth(r: float) -> int:
    """The samples :func:`pixel_filter` of ``r`` texels adds to a texture axis (0 for none): ceil(r/2) + 1 a side."""
    return 2 * (int(np.ceil(r / 2.0)) + 1) if r else 0


def pixel_filter(data: np.ndarray, centre: float, r: float, axis: int) -> tuple:
    """The texture ``data`` box-filtered along ``axis`` by ``r`` texels (a pixel), and its centre's new sample
    coordinate: at every sample, the mean over ``[x - r/2, x + r/2]`` of the samples' linear interpolant with zeros
    beyond (what the kernels' bilinear lookup reads), integrated exactly.  The support grows by ``r/2`` either side;
    where ``r`` is whole, the filtered samples at any phase, P apart, sum to the samples' sum over ``r``, so the
    image keeps the footprint's integral."""
    x = np.moveaxis(np.asarray(data, np.float64), axis, -1)
    n, grow = x.shape[-1], filter_growth(r) // 2
    y = np.concatenate([np.zeros(x.shape[:-1] + (1,)), x, np.zeros(x.shape[:-1] + (1,))], axis=-1)  # nodes -1 .. n
    F = np.concatenate([np.zeros(x.shape[:-1] + (1,)), np.cumsum((y[..., 1:] + y[..., :-1]) / 2.0, axis=-1)], axis=-1)

    def integral(t):  # of the interpolant from node -1 to t (texel coordinates), t clamped to [-1, n]
        t = np.clip(t, -1.0, float(n)) + 1.0
        k = np.minimum(np.floor(t).astype(int), n)
        f = t - k
        y0, y1 = y[..., k], y[..., np.minimum(k + 1, n + 1)]
        return F[..., k] + y0 * f + (y1 - y0) * f * f / 2.0

    at = np.arange(-grow, n + grow, dtype=np.float64)
    out = (integral(at + r / 2.0) - integral(at - r / 2.0)) / r
    return np.moveaxis(out, -1, axis).astype(data.dtype), centre + grow


def _axis_sampling(width, cell, omega, d_min, texel) -> tuple:
    """``(N, h, cell)`` of one texture axis whose support is ``width`` wide (world units).

    Cells: the 2 halves of the support, ``h = width / 2``.  Otherwise eq. 36 with the
    per-type period, ``N = 2^(m+1) omega / dw``, ``dw = 2 pi d_min / W(m=0)``, ``h = width / N``;
    or, with ``texel``, ``h = texel`` and the period ``N h`` a little beyond the support.
    """
    if cell:
        return 2, width / 2.0, True
    if texel is None:
        count = _fast_even(ceil(2.0 * omega * width / (2.0 * np.pi * d_min) + 1.0))
        return count, width / count, False
    return _fast_even(ceil(width / texel)), float(texel), False


def _filter_width(voxel, cell, pixel, texel) -> float:
    """The pixel filter's width in texels along a texture axis where the level's voxels project ``voxel`` wide (world
    units): the pixel where that is under :data:`FILTER_BELOW` pixels and the axis not cells, else 0 (no filter)."""
    return 0.0 if cell or pixel is None or texel is None or voxel >= FILTER_BELOW * pixel else pixel / texel


def _filtered_samples(count, h, cell, r) -> int:
    """The samples of one texture axis (:func:`_axis_sampling`'s ``count, h, cell``) after a pixel filter of ``r``
    texels (0: none; :func:`pixel_filter` grows the support)."""
    return _axis_samples(count, cell) + filter_growth(r)


def _axis_points(count, h, cell) -> tuple:
    """Sample offsets from the support centre along one axis, and the centre's sample coordinate:
    the 2 cell centres (a quarter of the support out), or the ``count + 1`` samples of the
    closed box ``[-count h / 2, count h / 2]``."""
    centre = 0.5 if cell else float(count // 2)
    return (np.arange(_axis_samples(count, cell)) - centre) * h, centre


def _axis_samples(count, cell) -> int:
    """How many samples :func:`_axis_points` gives along one axis."""
    return 2 if cell else count + 1


def plane_shape(nv: int, nu: int, P: int) -> tuple:
    """The shape of a texture of ``nv`` x ``nu`` samples in the texel pool, as P phase planes along u
    (:func:`~clwave.splat.tables.pack_texture`): (P, nv + 3, ceil(nu / P) + 2)."""
    return P, nv + 3, -(-nu // P) + 2


#: Host bytes a texel takes at the peak of making an orthographic view's textures (a perspective view's are made on
#: the device, docs/splatting.md §8): its half-spectrum (complex128, 8 bytes a
#: texel), the inverse FFT's float64 period (8), the centred and trimmed float32 copies (8) and the packed pool
#: with its concatenation (8)
HOST_TEXEL_BYTES = 32


def check_texels(texels: int, max_texels: int | None, what: str, fix: str) -> None:
    """Refuse footprint textures of more than ``max_texels`` float texels (the device budget of
    docs/splatting.md §6) in one line: ``what`` needs so many, and ``fix``."""
    if max_texels is not None and texels > max_texels:
        raise DeviceMemoryError(f"{what} need {texels:,} texels ({4 * texels / 2**20:,.0f} MiB), more than the "
                                f"{4 * max_texels / 2**20:,.0f} MiB allowed: {fix}")


def check_sampling(sampling):
    """``sampling`` one of :data:`SAMPLINGS` (a string: an array or a list is named, not hashed)."""
    if not isinstance(sampling, str) or sampling not in SAMPLINGS:
        raise InputError(f"footprint sampling must be one of {', '.join(SAMPLINGS)}, got {sampling!r}")


def check_omega_s(omega_s) -> float:
    """The footprint band ``omega_s`` (paper eq. 35) as a float in (0, :data:`OMEGA_S_MAX`], or the one line that
    refuses it (``--omega-s``'s words too)."""
    value = omega_s if isinstance(omega_s, float) else finite_number(omega_s, "omega_s")  # NaN fails the range
    if not 0 < value <= OMEGA_S_MAX:
        why = f"must be a positive band up to {OMEGA_S_MAX:g} (e.g. 14, paper eq. 35)"
        raise InputError(f"omega_s={omega_s!r} {why}", cli=f"--omega-s {value:g} {why}")
    return float(value)


def footprints(wavelet, spacing_zyx, n, u, v, bands, omega_s: float = 14.0, omega_min=None,
               sampling: str = "auto", tol: float = 0.0, texel=None, device=None, max_texels=None,
               phases=None, pixel=None) -> dict:
    """Footprint textures of the (level, key) pairs in ``bands`` for one view.

    Parameters
    ----------
    wavelet : SplineWavelet, name or order
    spacing_zyx : (dz, dy, dx)
        Voxel spacing in world units.
    n, u, v : (3,) arrays, world (x, y, z)
        Orthonormal view frame (paper eq. 31): n towards the camera, u right, v up.
    bands : iterable of (m, key)
        Levels (0 = the voxels' own B-splines) and 3-letter subband keys in (z, y, x) order.
    omega_s : float
        Band of eq. 35/36: texel spacing about ``pi d_min / omega_s`` at every level.
    omega_min : float, optional
        Least band of any texture in prototype units; default :data:`DEFAULT_OMEGA_MIN`.
    sampling : "auto", "fft", "spatial" or "cells"
        "auto": FFT for order >= 3, exact spatial sampling for Haar and linear; "cells"
        (Haar with u or v along a world axis, :func:`cell_axes`): along each such axis
        the exact values of the 2 cells between the knots, for nearest-sample lookup, and
        spatial samples along the other; the textures' sampling is then "cells", "cells-u"
        or "cells-v" (which axes are cells).
    tol : float
        Trim each texture to the bounding box of samples above ``tol`` times its peak
        magnitude (0: keep the tight projected support box).
    texel : float or dict, optional
        Sample spacing in world units, for every texture or per band (``{(m, key): texel}``),
        overriding the counts of eq. 36 (the splat renderer asks for an exact fraction of
        its pixel); the FFT period is then the smallest multiple of it that covers the
        support.  Not used along cell axes.
    max_texels : int, optional
        Refuse (:class:`DeviceMemoryError`) a view whose textures would hold more texels, before
        any is made.
    phases : dict, optional
        The phase planes P each band's texture takes in the renderer's texel pool (a pixel's
        whole number of texels, :func:`plane_shape`): the pool is refused past ``max_texels``
        too, before any texture is made.
    device : ComputeContext, optional
        Sample the FFT sampling's spectra there (:func:`device_spectra`, float32), all
        textures in one launch, instead of with NumPy (float64); the inverse FFTs stay on
        the host.
    pixel : float or dict, optional
        The image's pixel (world units; or per band, ``{(m, key): pixel}``): box-filter each texture by it along an
        axis where the level's voxels project narrower than :data:`FILTER_BELOW` pixels and the axis is not cells
        (:func:`pixel_filter`).

    Returns
    -------
    dict mapping (m, key) to :class:`Texture`, or to None where the footprint vanishes
    identically (psi along an axis parallel to n).
    """
    wav = wavelet_for(wavelet)
    d_xyz = spacing_xyz(spacing_zyx)
    n, u, v = orthonormal_frame(n, u, v)
    check_sampling(sampling)
    omega_s = check_omega_s(omega_s)
    if omega_min is None:
        omega_min = DEFAULT_OMEGA_MIN.get(wav.order, 64.0)
    if not (np.isfinite(omega_min) and omega_min >= 0):
        raise InputError(f"omega_min must be a number >= 0, got {omega_min!r}")
    for h in (texel.values() if isinstance(texel, dict) else [texel]):
        if h is not None and not (np.isfinite(h) and h > 0):
            raise InputError(f"texel must be a positive world length, got {h!r}")
    if sampling == "auto":
        sampling = "fft" if wav.order >= 3 else "spatial"
    cells = cell_axes(wav, u, v) if sampling == "cells" else (False, False)
    if sampling == "cells" and not any(cells):
        raise InputError("footprint sampling 'cells' needs Haar at a view with u or v along a world axis")
    name = {(True, True): "cells", (True, False): "cells-u", (False, True): "cells-v"}.get(cells, sampling)
    d_min = float(d_xyz.min())
    out, jobs = {}, []
    for band in bands:
        m, key = band
        m, key = int(m), check_key(key)
        if m < 0:
            raise InputError(f"footprint level must be >= 0, got {m}")
        if footprint_vanishes(key, n):
            out[(m, key)] = None
            continue
        extent = support_extent(wav, key, m, d_xyz)
        omega = max(float(omega_s), float(omega_min) / 2.0 ** m)
        out[(m, key)] = None
        h = texel.get((m, key)) if isinstance(texel, dict) else texel
        p = pixel.get((m, key)) if isinstance(pixel, dict) else pixel
        # per axis (count, texel, cell, the pixel filter's width in texels)
        jobs.append((m, key) + tuple(_axis_sampling(float(np.abs(w) @ extent), cell, omega, d_min, h)
                                     + (_filter_width(2.0 ** m * float(np.abs(w) @ d_xyz), cell, p, h),)
                                     for w, cell in ((u, cells[0]), (v, cells[1]))))
    texels = sum(_filtered_samples(*ju) * _filtered_samples(*jv) for _, _, ju, jv in jobs)
    fix = "give a lower omega_s (--omega-s), or render with the ray tracer (--method raytrace)"
    if any(ju[3] or jv[3] for _, _, ju, jv in jobs):  # filtered by a pixel many texels wide: more pixels, less filter
        fix = "render more pixels (--size), or " + fix
    check_texels(texels, max_texels, "the footprint textures of this view",
                 f"the voxel spacing is very uneven or omega_s high; {fix}")
    # their pool, P phase planes each where a pixel spans P texels (a needle's thin axis sets the texel, its long one
    # the pixel): weighed before a texture is made (a 1000:1 spacing made 9 GB of textures first)
    if phases is not None:  # the renderer's (ViewTables'): P a band
        pool = sum(prod(plane_shape(_filtered_samples(*jv), _filtered_samples(*ju),
                                    1 if ju[2] else phases.get((m, key), 1)))
                   for m, key, ju, jv in jobs)
        check_texels(pool, max_texels, "the texel pool (phase planes) of this view's footprint textures",
                     f"a pixel spans up to {max(phases.values(), default=1):,} texels of the volume's thinnest voxels "
                     f"(a very uneven spacing, or a wide extent); render more pixels (a camera's size, --size), a "
                     f"smaller extent, or with the ray tracer (--method raytrace)")
    # the host's memory, where a limit (ulimit -v) rather than the textures may be the cause
    check_fits(HOST_TEXEL_BYTES * texels, f"making the footprint textures of this view ({texels:,} texels)",
               f"free memory (or raise this process's limit), {fix}")
    spectra = {}
    if sampling == "fft" and device is not None:
        # 2-D spectra on the device; at axis-aligned views (every axis along u or v) the texture
        # is separable and its two 1-D transforms on the host are cheaper
        plans = {}
        for m, key, (nu, h_u, _, _), (nv, h_v, _, _) in jobs:
            scale, axes = slice_plan(wav, key, m, d_xyz, u, v, nu * h_u, nv * h_v)
            if any(alpha and beta for _, alpha, beta in axes):
                plans[(m, key)] = (scale, axes, nu, nv)
        spectra = dict(zip(plans, device_spectra(device, wav.order, list(plans.values()))))

    def make(job):
        m, key, (nu, h_u, cell_u, r_u), (nv, h_v, cell_v, r_v) = job
        if sampling == "fft":
            if (m, key) in spectra:
                period = scipy.fft.irfft2(spectra[(m, key)], s=(nv, nu), workers=workers, overwrite_x=True)
            else:
                period = fft_texture(wav, key, m, d_xyz, u, v, nu, nv, nu * h_u, nv * h_v, workers)
            data = _centred(period, np.float32)
            cu, cv = float(nu // 2), float(nv // 2)
        else:
            (aa, cu), (bb, cv) = _axis_points(nu, h_u, cell_u), _axis_points(nv, h_v, cell_v)
            shape = (len(bb), len(aa))
            data = exact_samples(wav, key, m, d_xyz, n, u, v,
                                       np.broadcast_to(aa, shape).reshape(-1),
                                       np.broadcast_to(bb[:, None], shape).reshape(-1))
            data = data.reshape(shape).astype(np.float32)
        data, cu, cv = _trim(data, cu, cv, float(tol))
        if r_u:
            data, cu = pixel_filter(data, cu, r_u, axis=1)
        if r_v:
            data, cv = pixel_filter(data, cv, r_v, axis=0)
        return Texture(np.ascontiguousarray(data), h_u, h_v, cu, cv, name, m, key)

    # numpy and pocketfft release the GIL: textures in parallel, largest first, where the
    # work outweighs the threads' overhead (from about 1e5 texels)
    if len(jobs) > 1 and cores() > 1 and sum(job[2][0] * job[3][0] for job in jobs) >= 1 << 17:
        workers = 1
        jobs.sort(key=lambda job: -job[2][0] * job[3][0])
        textures = thread_map(make, jobs)
    else:
        workers = -1
        textures = [make(job) for job in jobs]
    for tex in textures:
        out[(tex.level, tex.key)] = tex
    return out
