"""Footprint textures (paper §4, docs/splatting.md §1-2) against independent line integrals.

The oracle integrates the closed-form 3-D prototype product (``SplineWavelet.prototype``,
Cox-de Boor) along each line with composite Gauss-Legendre panels between the crossings of
every knot plane; it is itself checked against ``scipy.integrate.quad``.  Expected values
come from the math (Table I, the projection-slice constant, the integral of the basis,
the scaling relation, the support box), never from the module's own output.
"""

import zlib

import numpy as np
import pytest
from scipy.integrate import quad

from clwave.model.bspline import SplineWavelet
from clwave.errors import DeviceMemoryError, InputError
from clwave.model.geometry import projected_halfwidths, view_frame
from clwave.splat.spatial import line_integral
from clwave.splat.spectral import centred_fourier
from clwave.splat.textures import DEFAULT_OMEGA_MIN, Texture, cell_axes, footprints, sample_count

KEYS = [z + y + x for z in "ad" for y in "ad" for x in "ad"]  # array order (z, y, x)
OBLIQUE = [(30.0, 20.0), (-70.0, -15.0), (45.0, 35.26)]
AXIS = [(0.0, 0.0), (90.0, 0.0), (0.0, 90.0)]
SPACINGS = [(1.0, 1.0, 1.0), (2.0, 1.0, 0.5)]  # (dz, dy, dx)


# ----------------------------------------------------------------------------- oracle
def frame(azimuth, elevation):
    """Paper eq. 31, with cos(90 deg) ~ 6e-17 read as the exact 0 it stands for."""
    a, b = np.radians(azimuth), np.radians(elevation)
    vecs = (np.array([np.cos(a) * np.cos(b), np.sin(a) * np.cos(b), np.sin(b)]),
            np.array([-np.sin(a), np.cos(a), 0.0]),
            np.array([-np.cos(a) * np.sin(b), -np.sin(a) * np.sin(b), np.cos(b)]))
    return tuple(np.where(np.abs(x) < 1e-13, 0.0, x) for x in vecs)


def _line_setup(w, key, m, spacing, n, u, v, a, b):
    """Prototype coordinate ``c_i + g_i t`` of each world axis i along the lines through (a, b)."""
    d = np.asarray(spacing, float)[::-1]
    kx = key[::-1]
    cs = [2.0 ** -m * (a * u[i] + b * v[i]) / d[i] + w.support(kx[i]) / 2.0 for i in range(3)]
    gs = [2.0 ** -m * n[i] / d[i] for i in range(3)]
    return kx, cs, gs


def oracle(w, key, m, spacing, n, u, v, a, b, panels=2, nodes=8):
    """∫ 2^(-3m/2) prod_i P_i(c_i + g_i t) dt by composite Gauss-Legendre between knot crossings."""
    a, b = np.broadcast_arrays(np.asarray(a, float).ravel(), np.asarray(b, float).ravel())
    kx, cs, gs = _line_setup(w, key, m, spacing, n, u, v, a, b)
    reach = np.sqrt(sum((2.0 ** m * w.support(L) * d) ** 2 for L, d in zip(kx, np.asarray(spacing)[::-1])))
    breaks = [np.full((a.size, 1), -reach), np.full((a.size, 1), reach)]
    for i in range(3):
        if gs[i] != 0.0:  # every half-integer plane (phi knots are a subset)
            knots = np.arange(0.0, w.support(kx[i]) + 0.25, 0.5)
            breaks.append((knots[None, :] - cs[i][:, None]) / gs[i])
    t = np.sort(np.clip(np.concatenate(breaks, axis=1), -reach, reach), axis=1)
    x_g, w_g = np.polynomial.legendre.leggauss(nodes)
    edges = t[:, :-1, None] + (t[:, 1:, None] - t[:, :-1, None]) * np.linspace(0, 1, panels + 1)
    lo, hi = edges[..., :-1], edges[..., 1:]
    tt = 0.5 * (lo + hi)[..., None] + 0.5 * (hi - lo)[..., None] * x_g
    f = np.full(tt.shape, 2.0 ** (-1.5 * m))
    for i in range(3):
        f *= w.prototype(kx[i], cs[i][:, None, None, None] + gs[i] * tt)
    return np.einsum("pksg,g,pks->p", f, w_g, 0.5 * (hi - lo))


def sample_points(tex, count, seed):
    """Random sample indices plus the centre row and column (they cross every kink)."""
    rng = np.random.default_rng(seed)
    nv, nu = tex.data.shape
    iv = np.concatenate([rng.integers(0, nv, count), np.full(9, int(tex.centre_v)),
                         np.linspace(0, nv - 1, 9).astype(int)])
    iu = np.concatenate([rng.integers(0, nu, count), np.linspace(0, nu - 1, 9).astype(int),
                         np.full(9, int(tex.centre_u))])
    a, b = tex.coordinates()
    return iv, iu, a[iu], b[iv]


def aaa_peak(w, m, spacing, n, u, v):
    """phi x phi x phi footprints are symmetric and log-concave: the peak is at the centre."""
    return float(oracle(w, "aaa", m, spacing, n, u, v, 0.0, 0.0)[0])


def max_errors(order, view, m, spacing, sampling="auto", count=24, **kw):
    """{key: max |texture - oracle| / peak of 'aaa'} over sample points, and the textures."""
    w = SplineWavelet(order)
    n, u, v = frame(*view)
    tex = footprints(w, spacing, n, u, v, [(m, k) for k in KEYS], sampling=sampling, **kw)
    peak = aaa_peak(w, m, spacing, n, u, v)
    errs = {}
    for (mm, key), t in tex.items():
        if t is None:
            continue
        iv, iu, a, b = sample_points(t, count, seed=zlib.crc32(repr((order, view, m, key)).encode()))
        want = oracle(w, key, m, spacing, n, u, v, a, b)
        if order == 1:  # Haar footprints jump where a line runs in a knot plane: either side is right
            near = [oracle(w, key, m, spacing, n, u, v, a + da, b + db) for da in (-1e-9, 1e-9) for db in (-1e-9, 1e-9)]
            smooth = np.ptp(near, axis=0) < 1e-6 * peak
            iv, iu, want = iv[smooth], iu[smooth], want[smooth]
        errs[key] = np.max(np.abs(t.data[iv, iu] - want)) / peak
    return errs, tex


# ----------------------------------------------------------------------------- device spectra
@pytest.mark.parametrize("order", (1, 2, 3, 4, 6))
def test_device_spectra_give_the_numpy_textures(cc, order):
    """cl/splat/footprint.cl against its NumPy twin (float64 spectra, same inverse FFT): every type at
    levels 0-2, oblique and axis-aligned views (those stay separable on the host), both spacings,
    within float32 rounding of each texture's peak."""
    bands = [(m, k) for m in (0, 1, 2) for k in KEYS]
    for view in OBLIQUE + AXIS:
        n, u, v = frame(*view)
        for spacing in SPACINGS:
            host = footprints(order, spacing, n, u, v, bands, sampling="fft")
            dev = footprints(order, spacing, n, u, v, bands, sampling="fft", device=cc)
            assert [band for band, t in host.items() if t is None] == [band for band, t in dev.items() if t is None]
            for band, t in host.items():
                if t is not None:
                    assert dev[band].data.shape == t.data.shape
                    assert np.max(np.abs(dev[band].data - t.data)) <= 2e-6 * np.max(np.abs(t.data)), (view, band)


def test_device_textures_within_1e3_of_the_line_integrals(cc):
    for view in OBLIQUE[1:]:
        errs, tex = max_errors(4, view, 1, SPACINGS[1], device=cc)
        assert len(errs) == 8 and max(errs.values()) <= 1e-3, errs


# ----------------------------------------------------------------------------- sampling
def test_table_one_sample_counts():
    table = {1: [9, 17, 32, 63], 2: [25, 48, 94, 187], 4: [56, 110, 218, 434]}
    for j, counts in table.items():
        assert [sample_count(j, m) for m in range(4)] == counts


def test_view_vectors_are_eq31_and_right_handed():
    for az, el in OBLIQUE + AXIS:
        n, u, v = view_frame(az, el)
        a, b = np.radians(az), np.radians(el)
        assert np.allclose(n, [np.cos(a) * np.cos(b), np.sin(a) * np.cos(b), np.sin(b)], atol=1e-15)
        assert np.allclose(np.cross(u, v), n, atol=1e-15)
        assert np.allclose(np.array([n, u, v]) @ np.array([n, u, v]).T, np.eye(3), atol=1e-15)


@pytest.mark.parametrize("j", (1, 2, 3, 4))
def test_centred_transform_is_the_shifted_fourier_transform(j):
    """G(w) = P^(w) e^(i w S/2), with P^ from bspline.py: real (phi, even psi) or imaginary (odd psi)."""
    w = SplineWavelet(j)
    x = np.linspace(-80, 80, 1601)
    for letter in "ad":
        want = w.fourier(letter, x) * np.exp(0.5j * x * w.support(letter))
        got = centred_fourier(w, letter, x)
        assert np.max(np.abs(got - want)) < 1e-13
        odd = letter == "d" and j % 2 == 1
        assert np.max(np.abs(got.real if odd else got.imag)) == 0.0


# ----------------------------------------------------------------------------- exact line integrals
def test_oracle_agrees_with_quad():
    w = SplineWavelet(4)
    n, u, v = frame(30.0, 20.0)
    spacing, m, key = (2.0, 1.0, 0.5), 1, "dad"
    pts = [(0.3, -0.7), (4.0, 2.5)]
    got = oracle(w, key, m, spacing, n, u, v, [p[0] for p in pts], [p[1] for p in pts])
    for (a, b), value in zip(pts, got):
        kx, cs, gs = _line_setup(w, key, m, spacing, n, u, v, np.array(a), np.array(b))
        knots = sorted({float((k - cs[i]) / gs[i]) for i in range(3) for k in np.arange(0, 7.25, 0.5)})
        inside = [t for t in knots if -40 < t < 40]

        def f(t):
            return 2.0 ** (-1.5 * m) * np.prod([w.prototype(kx[i], cs[i] + gs[i] * t) for i in range(3)])

        ref = quad(f, -40, 40, points=inside, limit=400, epsabs=1e-14, epsrel=1e-12)[0]
        assert abs(value - ref) < 1e-12


@pytest.mark.parametrize("j", (1, 2, 3, 4))
def test_line_integral_is_exact(j):
    w = SplineWavelet(j)
    rng = np.random.default_rng(j)
    a, b = rng.uniform(-6, 6, 40), rng.uniform(-6, 6, 40)
    for view in [(30.0, 20.0), (0.0, 0.0), (10.0, 5.0)]:
        n, u, v = frame(*view)
        for spacing in SPACINGS:
            for key in ("aaa", "aad", "daa", "ddd"):
                for m in (0, 2):
                    s = 2.0 ** m
                    got = line_integral(w, key, m, spacing, n, u, v, s * a, s * b)
                    want = oracle(w, key, m, spacing, n, u, v, s * a, s * b)
                    assert np.max(np.abs(got - want)) < 1e-13 * max(1.0, np.max(np.abs(want)))


def test_line_integral_shapes_and_scaling_relation():
    """T_m(a, b) = 2^(-m/2) T_0(a / 2^m, b / 2^m), with T_0 from the oracle."""
    w = SplineWavelet(2)
    n, u, v = frame(-70.0, -15.0)
    a, b = np.meshgrid(np.linspace(-9, 9, 7), np.linspace(-9, 9, 5))
    for m in (1, 2, 3):
        got = line_integral(w, "dad", m, (2.0, 1.0, 0.5), n, u, v, a, b)
        assert got.shape == a.shape
        want = 2.0 ** (-m / 2) * oracle(w, "dad", 0, (2.0, 1.0, 0.5), n, u, v, a / 2 ** m, b / 2 ** m)
        assert np.max(np.abs(got.ravel() - want)) < 1e-14


# ----------------------------------------------------------------------------- textures vs oracle
@pytest.mark.parametrize("spacing", SPACINGS)
@pytest.mark.parametrize("m", (0, 1))
@pytest.mark.parametrize("view", OBLIQUE + AXIS)
def test_cubic_fft_textures_within_1e3_of_the_aaa_peak(view, m, spacing):
    errs, tex = max_errors(4, view, m, spacing)
    assert {t.sampling for t in tex.values() if t is not None} == {"fft"}
    assert len(errs) == (8 if view in OBLIQUE else 4)  # psi along n: 4 types vanish
    assert max(errs.values()) <= 1e-3, errs


@pytest.mark.parametrize("m", (0, 1))
def test_quintic_fft_textures_within_1e4_of_the_aaa_peak(m):
    """Order 6 (psi with 2 vanishing moments: spectral.psi_poly's s^M factor) at its DEFAULT_OMEGA_MIN."""
    for view in OBLIQUE + AXIS:
        for spacing in SPACINGS:
            errs, tex = max_errors(6, view, m, spacing)
            assert {t.sampling for t in tex.values() if t is not None} == {"fft"}
            assert max(errs.values()) <= 1e-4, (view, spacing, errs)


@pytest.mark.parametrize("order", (1, 2))
@pytest.mark.parametrize("view", OBLIQUE + AXIS[:2])
def test_haar_and_linear_spatial_textures_are_exact(order, view):
    """Exact up to the float32 of the texture, at m = 0 and 1 and both spacings."""
    for m in (0, 1):
        for spacing in SPACINGS:
            errs, tex = max_errors(order, view, m, spacing, count=16)
            assert {t.sampling for t in tex.values() if t is not None} == {"spatial"}
            assert max(errs.values()) <= 1e-6, errs  # float32 rounding; float64 is line_integral


@pytest.mark.parametrize("view", AXIS + [(180.0, 0.0), (-90.0, -90.0)])
@pytest.mark.parametrize("spacing", SPACINGS)
def test_haar_cells_at_axis_views_are_exact_everywhere(view, spacing):
    """Nearest-sample lookup of the 2 x 2 cells gives the exact footprint at any point of the
    support box, not only at the samples: the jumps lie on the cell edges."""
    w = SplineWavelet(1)
    n, u, v = frame(*view)
    assert cell_axes(w, u, v) == (True, True)
    rng = np.random.default_rng(3)
    for m in (0, 2):
        tex = footprints(w, spacing, n, u, v, [(m, k) for k in KEYS], sampling="cells")
        peak = aaa_peak(w, m, spacing, n, u, v)
        assert sum(t is not None for t in tex.values()) == 4  # psi along n vanishes
        for (_, key), t in tex.items():
            if t is None:
                continue
            hu, hv = projected_halfwidths(w, key, m, spacing, u, v)
            assert t.data.shape == (2, 2) and (t.h_u, t.h_v) == pytest.approx((hu, hv))
            a, b = rng.uniform(-hu, hu, 200), rng.uniform(-hv, hv, 200)
            a, b = a[np.abs(a) > 1e-6 * hu], b[np.abs(b) > 1e-6 * hv]  # off the middle knots
            k = min(len(a), len(b))
            a, b = a[:k], b[:k]
            iu = np.floor(a / t.h_u + t.centre_u + 0.5).astype(int)
            iv = np.floor(b / t.h_v + t.centre_v + 0.5).astype(int)
            want = oracle(w, key, m, spacing, n, u, v, a, b)
            assert np.max(np.abs(t.data[iv, iu] - want)) <= 1e-6 * peak


MIXED = [(0.0, 10.0), (90.0, 25.0), (-180.0, -40.0), (30.0, 0.0), (-70.0, 0.0)]  # u or v a world axis


@pytest.mark.parametrize("view", MIXED)
@pytest.mark.parametrize("spacing", SPACINGS)
def test_haar_cells_along_the_one_world_axis_are_exact(view, spacing):
    """With only u (azimuth a multiple of 90 deg) or only v (elevation 0) along a world axis, the
    texture is the 2 cells along that axis and samples along the other: exact at any point
    along the cell axis (nearest cell), at the sample offsets along the other."""
    w = SplineWavelet(1)
    n, u, v = frame(*view)
    cells = (view[0] % 90 == 0, view[1] == 0)
    assert cell_axes(w, u, v) == cells
    rng = np.random.default_rng(5)
    for m in (0, 2):
        tex = footprints(w, spacing, n, u, v, [(m, k) for k in KEYS], sampling="cells", texel=0.07)
        peak = aaa_peak(w, m, spacing, n, u, v)
        assert all(t is not None for t in tex.values())  # no world axis along n
        for (_, key), t in tex.items():
            if t is None:
                continue
            assert t.sampling == ("cells-u" if cells[0] else "cells-v") and t.cells == cells
            hu, hv = projected_halfwidths(w, key, m, spacing, u, v)
            cell_h, cell_axis = (t.h_u, 1) if cells[0] else (t.h_v, 0)
            assert t.data.shape[cell_axis] == 2 and cell_h == pytest.approx(hu if cells[0] else hv)
            assert (t.h_v if cells[0] else t.h_u) == 0.07  # the other axis keeps the asked texel
            x = rng.uniform(-1.0, 1.0, 300) * (hu if cells[0] else hv)
            x = x[np.abs(x) > 1e-6 * cell_h]  # off the middle knot
            i_cell = np.floor(x / cell_h + 0.5 + 0.5).astype(int)  # nearest of the 2 cells
            a_s, b_s = t.coordinates()
            i_s = rng.integers(0, t.data.shape[1 - cell_axis], x.size)
            if cells[0]:
                got, want = t.data[i_s, i_cell], oracle(w, key, m, spacing, n, u, v, x, b_s[i_s])
            else:
                got, want = t.data[i_cell, i_s], oracle(w, key, m, spacing, n, u, v, a_s[i_s], x)
            assert np.max(np.abs(got - want)) <= 1e-6 * peak


def test_cells_need_haar_with_a_world_axis_in_the_image():
    n, u, v = frame(30.0, 20.0)
    assert cell_axes(1, u, v) == (False, False)
    with pytest.raises(InputError, match="cells"):
        footprints(1, (1, 1, 1), n, u, v, [(0, "aaa")], sampling="cells")
    n, u, v = frame(0.0, 0.0)
    assert cell_axes(2, u, v) == (False, False)
    with pytest.raises(InputError, match="cells"):
        footprints(2, (1, 1, 1), n, u, v, [(0, "aaa")], sampling="cells")


@pytest.mark.parametrize("order, bound", [(1, 0.1), (2, 0.2)])
def test_fft_rings_for_haar_and_linear_at_axis_views(order, bound):
    """Why "auto" takes the spatial path for orders 1-2: the band-limited footprint rings at
    the jumps (Haar) and kinks (linear) of axis-aligned views, far beyond 1e-2 (docs/splatting.md §1:
    1.0 and 0.53 at omega_s = 14; Haar here even with the jump samples themselves left out);
    oblique views are smoother but still above 1e-2."""
    errs, tex = max_errors(order, (0.0, 0.0), 0, (1.0, 1.0, 1.0), sampling="fft")
    assert {t.sampling for t in tex.values() if t is not None} == {"fft"}
    assert max(errs.values()) > bound
    errs, _ = max_errors(order, (30.0, 20.0), 0, (1.0, 1.0, 1.0), sampling="fft")
    assert max(errs.values()) > 1e-2


def test_paper_band_alone_is_not_enough_for_cubic_axis_views():
    """omega_min exists because omega_s = 14 leaves ~3e-2 at the axis view (docs/splatting.md §1)."""
    errs, _ = max_errors(4, (0.0, 0.0), 0, (1.0, 1.0, 1.0), omega_min=0.0)
    assert max(errs.values()) > 1e-2
    assert DEFAULT_OMEGA_MIN[4] <= 64


def test_quadratic_fft_default_accuracy():
    for view in [(30.0, 20.0), (0.0, 0.0)]:
        errs, tex = max_errors(3, view, 0, (1.0, 1.0, 1.0))
        assert {t.sampling for t in tex.values() if t is not None} == {"fft"}
        assert max(errs.values()) <= 1e-3, errs


def test_spatial_path_for_cubic_is_exact_too():
    errs, tex = max_errors(4, (0.0, 0.0), 1, (2.0, 1.0, 0.5), sampling="spatial", count=8)
    assert {t.sampling for t in tex.values() if t is not None} == {"spatial"}
    assert max(errs.values()) <= 1e-6


# ----------------------------------------------------------------------------- structure
@pytest.mark.parametrize("view, axis", [((0.0, 0.0), 2), ((90.0, 0.0), 1), ((0.0, 90.0), 0),
                                        ((180.0, 0.0), 2), ((0.0, -90.0), 0)])
def test_psi_along_the_view_direction_vanishes(view, axis):
    """key[axis] is the letter of the world axis parallel to n (array order z, y, x)."""
    n, u, v = frame(*view)
    tex = footprints(4, (1.0, 1.0, 1.0), n, u, v, [(1, k) for k in KEYS])
    for (m, key), t in tex.items():
        assert (t is None) == (key[axis] == "d"), key


def test_no_type_vanishes_off_axis():
    for view in OBLIQUE + [(0.5, 0.0), (0.0, 89.5)]:
        n, u, v = frame(*view)
        tex = footprints(2, (1.0, 1.0, 1.0), n, u, v, [(0, k) for k in KEYS], omega_s=4.0)
        assert all(t is not None for t in tex.values())


@pytest.mark.parametrize("order", (2, 4))
def test_texture_integral_is_the_basis_integral(order):
    """∫∫T da db = ∫B d^3p = 2^(3m/2) det(D) prod_a ∫P_a: ∫phi = 1, ∫psi = 0."""
    spacing = (2.0, 1.0, 0.5)
    n, u, v = frame(-70.0, -15.0)
    for m in (0, 2):
        tex = footprints(order, spacing, n, u, v, [(m, k) for k in KEYS])
        volume = 2.0 ** (1.5 * m) * np.prod(spacing)
        for (mm, key), t in tex.items():
            total = float(t.data[:-1, :-1].astype(float).sum()) * t.h_u * t.h_v  # one period
            want = volume if key == "aaa" else 0.0
            # FFT: the DC term, exact; spatial: the trapezoid rule of a C^1 footprint
            tol = 1e-6 if t.sampling == "fft" else 2e-3
            assert abs(total - want) <= tol * volume, (key, total, want)


def test_texture_box_is_the_tight_projected_support_box():
    w = SplineWavelet(1)
    spacing = (2.0, 1.0, 0.5)
    d = np.array(spacing)[::-1]
    n, u, v = frame(30.0, 20.0)
    for m, key in [(0, "aaa"), (1, "daa"), (2, "dda"), (0, "add")]:
        edges = 2.0 ** m * np.array([w.support(L) for L in key[::-1]]) * d  # (x, y, z)
        half_u, half_v = 0.5 * np.abs(u) @ edges, 0.5 * np.abs(v) @ edges
        t = footprints(w, spacing, n, u, v, [(m, key)])[(m, key)]
        assert np.allclose(t.box, (-half_u, half_u, -half_v, half_v), rtol=0, atol=1e-12)
        assert np.allclose(projected_halfwidths(w, key, m, spacing, u, v), (half_u, half_v))
        assert t.centre_u == (t.data.shape[1] - 1) / 2 and t.centre_v == (t.data.shape[0] - 1) / 2
    # the box is tight: the line through the corner that reaches furthest along u
    # meets the support just inside the edge and misses it just outside
    edges = np.array([1.0, 1.0, 1.0]) * d
    half_u = 0.5 * np.abs(u) @ edges
    corner_b = 0.5 * np.sign(u) * edges @ v
    eps = 1e-3 * half_u
    inside, outside = oracle(w, "aaa", 0, spacing, n, u, v, [half_u - eps, half_u + eps], corner_b)
    assert inside > 0 and outside == 0


def test_texture_sampling_follows_eq36_per_type():
    """N_u >= ceil(2^(m+1) omega W_u(0) / (2 pi d_min) + 1), even, and h_u N_u = W_u."""
    spacing = (2.0, 1.0, 0.5)
    d = np.array(spacing)[::-1]
    n, u, v = frame(30.0, 20.0)
    for order, omega_min in [(4, DEFAULT_OMEGA_MIN[4]), (2, 0.0)]:
        w = SplineWavelet(order)
        tex = footprints(w, spacing, n, u, v, [(m, "dad") for m in range(4)])
        for (m, key), t in tex.items():
            omega = max(14.0, omega_min / 2 ** m)
            W0 = np.abs(u) @ (np.array([w.support(L) for L in key[::-1]]) * d)
            nu = t.data.shape[1] - 1
            assert nu % 2 == 0 and nu >= np.ceil(2 ** (m + 1) * omega * W0 / (2 * np.pi * 0.5) + 1)
            assert np.isclose(t.h_u * nu, 2 ** m * W0)
            assert t.data.dtype == np.float32 and t.level == m and t.key == key


def test_tol_trims_to_the_samples_that_matter():
    n, u, v = frame(30.0, 20.0)
    full = footprints(4, (1.0, 1.0, 1.0), n, u, v, [(1, "dda")])[(1, "dda")]
    cut = footprints(4, (1.0, 1.0, 1.0), n, u, v, [(1, "dda")], tol=1e-3)[(1, "dda")]
    assert isinstance(cut, Texture) and cut.data.size < full.data.size
    r0, c0 = int(full.centre_v - cut.centre_v), int(full.centre_u - cut.centre_u)
    block = full.data[r0:r0 + cut.data.shape[0], c0:c0 + cut.data.shape[1]]
    assert np.array_equal(block, cut.data)
    rest = full.data.copy()
    rest[r0:r0 + cut.data.shape[0], c0:c0 + cut.data.shape[1]] = 0
    assert np.max(np.abs(rest)) <= 1e-3 * np.max(np.abs(full.data))


def test_texel_override_keeps_accuracy_and_alignment():
    n, u, v = frame(-70.0, -15.0)
    w = SplineWavelet(4)
    texel = {(1, "ada"): 0.04, (2, "aaa"): 0.05}  # per band
    tex = footprints(w, (1.0, 1.0, 1.0), n, u, v, list(texel), texel=texel)
    for (m, key), t in tex.items():
        assert t.h_u == t.h_v == texel[(m, key)] and t.centre_u == int(t.centre_u)
        iv, iu, a, b = sample_points(t, 20, seed=m)
        want = oracle(w, key, m, (1.0, 1.0, 1.0), n, u, v, a, b)
        assert np.max(np.abs(t.data[iv, iu] - want)) <= 1e-3 * aaa_peak(w, m, (1.0,) * 3, n, u, v)


def test_input_validation():
    n, u, v = frame(30.0, 20.0)
    with pytest.raises(InputError, match="key"):
        footprints(4, (1, 1, 1), n, u, v, [(1, "adx")])
    with pytest.raises(InputError, match="orthonormal"):
        footprints(4, (1, 1, 1), n, u, 2 * v, [(1, "aaa")])
    with pytest.raises(InputError, match="spacing"):
        footprints(4, (1, 0, 1), n, u, v, [(1, "aaa")])
    with pytest.raises(InputError, match="sampling"):
        footprints(4, (1, 1, 1), n, u, v, [(1, "aaa")], sampling="gpu")
    with pytest.raises(InputError, match="level"):
        footprints(4, (1, 1, 1), n, u, v, [(-1, "aaa")])
    with pytest.raises(InputError, match="texel"):
        footprints(4, (1, 1, 1), n, u, v, [(1, "aaa")], texel={(1, "aaa"): 0.1, (2, "aaa"): -0.1})


def test_textures_over_the_texel_cap_are_refused_before_any_is_made():
    n, u, v = view_frame(30.0, 20.0)
    bands = {(0, "aaa"): 0.05, (1, "dda"): 0.1}
    made = footprints("cubic", (1.0, 1.0, 1.0), n, u, v, bands)
    texels = sum(t.data.size for t in made.values())
    assert footprints("cubic", (1.0, 1.0, 1.0), n, u, v, bands, max_texels=texels).keys() == made.keys()
    with pytest.raises(DeviceMemoryError, match=f"need {texels:,} texels .*--method raytrace"):
        footprints("cubic", (1.0, 1.0, 1.0), n, u, v, bands, max_texels=texels - 1)


def test_textures_over_the_host_memory_are_refused_before_any_is_made(monkeypatch):
    """Within the device cap but more than the host could hold while making them: a HostMemoryError in one line."""
    from clwave.device import memory
    from clwave.splat.textures import HOST_TEXEL_BYTES

    n, u, v = view_frame(30.0, 20.0)
    bands = {(0, "aaa"): 0.05, (1, "dda"): 0.1}
    texels = sum(t.data.size for t in footprints("cubic", (1.0, 1.0, 1.0), n, u, v, bands).values())
    monkeypatch.setattr(memory, "available_bytes", lambda: HOST_TEXEL_BYTES * texels)
    assert footprints("cubic", (1.0, 1.0, 1.0), n, u, v, bands, max_texels=texels)
    monkeypatch.setattr(memory, "available_bytes", lambda: HOST_TEXEL_BYTES * texels - 1)
    with pytest.raises(memory.HostMemoryError, match=f"{texels:,} texels.* available; .*--method raytrace"):
        footprints("cubic", (1.0, 1.0, 1.0), n, u, v, bands, max_texels=texels)
