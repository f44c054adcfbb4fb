"""Analytic phantoms: samples equal the formula at voxel centres, geometry and errors."""

import math

import numpy as np
import pytest

from clwave.errors import InputError
from clwave.io.phantoms import NAMES, analytic, phantom
from clwave.model.volume import Volume


def centres(n):
    """World (x, y, z) of every voxel centre of an n³ grid, in C order of (i, j, k)."""
    c = np.arange(n) - (n - 1) / 2
    z, y, x = np.meshgrid(c, c, c, indexing="ij")
    return np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)


def hydrogen_independent(x, y, z):
    """|psi_320|² from spherical coordinates, scaled by its maximum 4·6⁴·e⁻⁴ (at r = 6)."""
    r = math.sqrt(x * x + y * y + z * z)
    cos_t = z / r if r > 0 else 0.0
    return (r * r * math.exp(-r / 3) * (3 * cos_t ** 2 - 1)) ** 2 / (4 * 6 ** 4 * math.exp(-4))


@pytest.mark.parametrize("name", NAMES)
def test_volume_layout(name):
    vol = phantom(name, 10)
    assert isinstance(vol, Volume)
    assert vol.shape == (10, 10, 10) and vol.channels == 1
    assert vol.spacing == (1.0, 1.0, 1.0) and vol.origin == (0.0, 0.0, 0.0)
    assert vol.data.dtype == np.float32
    assert vol.data.min() >= 0.0 and vol.data.max() <= 1.0


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("n", [2, 9, 16])
def test_samples_equal_analytic_at_voxel_centres(name, n):
    vol = phantom(name, n)
    f = analytic(name, n)
    values = f(centres(n))
    assert values.dtype == np.float64 and values.shape == (n ** 3,)
    np.testing.assert_array_equal(vol.data, values.astype(np.float32).reshape(n, n, n))
    # the Volume's own voxel -> world map gives the same points
    idx = np.array([[0, 0, 0], [n - 1, 1, n // 2], [n // 2, n - 1, 0]])
    np.testing.assert_array_equal(vol.data[tuple(idx.T)],
                                  f(vol.voxel_to_world(idx)).astype(np.float32))


def test_hydrogen_on_z_axis_matches_closed_form():
    n = 33                                   # odd: the column j = k = 16 is the z axis
    vol, f = phantom("hydrogen", n), analytic("hydrogen", n)
    for i in (0, 5, 10, 12, 20, 32):
        z = i - 16                           # world
        u = z * 36 / n                       # Bohr radii
        expected = 4 * u ** 4 * math.exp(-2 * abs(u) / 3) / (4 * 6 ** 4 * math.exp(-4))
        assert vol.data[i, 16, 16] == pytest.approx(expected, rel=1e-6)
        assert f(np.array([[0.0, 0.0, z]]))[0] == pytest.approx(expected, rel=1e-13)
    # off the axis, against the spherical form
    p = np.array([[3.0, -4.0, 7.5], [10.0, 2.0, 0.0], [-1.0, 6.0, -9.0]])
    got = f(p)
    for q, g in zip(p * 36 / n, got):
        assert g == pytest.approx(hydrogen_independent(*q), rel=1e-12)


def test_hydrogen_maximum_is_one_at_r6_on_the_axis():
    n = 64
    f = analytic("hydrogen", n)
    peak = 6 * n / 36                        # world z of r = 6 Bohr radii
    assert f(np.array([[0.0, 0.0, peak], [0.0, 0.0, -peak]])) == pytest.approx([1.0, 1.0], abs=1e-15)
    t = np.linspace(-n, n, 20001)
    line = f(np.stack([0 * t, 0 * t, t], axis=1))
    assert line.max() <= 1.0 and line.max() > 1 - 1e-7
    rng = np.random.default_rng(5)
    assert f(rng.uniform(-n / 2, n / 2, (20000, 3))).max() <= 1.0
    assert phantom("hydrogen", n).data.max() <= 1.0


def test_hydrogen_symmetry_and_axis_order():
    n = 32
    d = phantom("hydrogen", n).data
    np.testing.assert_array_equal(d, d[::-1])                       # z -> -z
    np.testing.assert_array_equal(d, np.rot90(d, 1, axes=(1, 2)))   # 90° about z
    np.testing.assert_array_equal(d, d[:, :, ::-1])                 # x -> -x
    # the 3d_z² lobes lie along z = array axis 0: more mass far along z than along x
    c = np.arange(n) - (n - 1) / 2
    mz = float((d * (c ** 2)[:, None, None]).sum())
    mx = float((d * (c ** 2)[None, None, :]).sum())
    assert mz > 1.5 * mx
    # along the z axis the peak is 1; in the xy plane (the torus) it is 1/4
    d33 = phantom("hydrogen", 33).data
    assert d33[:, 16, 16].max() > 0.9
    assert 0.2 < d33[16, 16, :].max() <= 0.25


def test_marschner_lobb_values():
    n = 33
    vol, f = phantom("marschner-lobb", n), analytic("marschner-lobb", n)
    # centre: (1 - sin 0 + 0.25 (1 + cos(12π cos 0))) / 2.5 = 1.5 / 2.5
    assert vol.data[16, 16, 16] == np.float32(0.6)
    assert f(np.zeros((1, 3)))[0] == pytest.approx(0.6, abs=1e-15)

    def ml(x, y, z):
        r = math.hypot(x, y)
        rho = math.cos(2 * math.pi * 6 * math.cos(math.pi * r / 2))
        return (1 - math.sin(math.pi * z / 2) + 0.25 * (1 + rho)) / (2 * 1.25)

    p = np.array([[3.0, -5.0, 7.0], [-16.0, 16.0, -16.0], [0.5, 0.0, -2.5]])
    for q, g in zip(p * 2 / n, f(p)):
        assert g == pytest.approx(ml(*q), abs=1e-14)
    # z is array axis 0: ML falls with z (the -sin(πz/2) term)
    d = vol.data
    assert d[0].mean() > d[-1].mean() + 0.5


def test_shepp_logan_regions():
    n = 64
    vol, f = phantom("shepp-logan", n), analytic("shepp-logan", n)
    d = vol.data
    s = n / 2                                # world units per domain unit
    pts = np.array([
        [0.0, 0.0, 0.0],       # inside skull and brain: 1 - 0.8
        [0.0, 0.89, 0.0],      # skull shell (between the two outer ellipsoids): 1
        [0.0, -0.9, 0.0],
        [0.0, 0.35, -0.15],    # ellipsoid 5 centre: 1 - 0.8 + 0.1
        [0.2179, -0.0306, 0.0],  # ventricle (ellipsoid 3): 1 - 0.8 - 0.2, exactly 0
        [0.0, 0.0, 0.95],      # above the head: 0
        [0.95, 0.95, 0.95],    # corner: 0
    ]) * s
    np.testing.assert_array_equal(f(pts), [0.2, 1.0, 1.0, 0.3, 0.0, 0.0, 0.0])
    assert d.min() == 0.0 and d.max() == 1.0      # nowhere negative (no -5.6e-17)
    for corner in [(0, 0, 0), (0, 0, -1), (-1, -1, -1), (0, -1, 0)]:
        assert d[corner] == 0.0
    c = n // 2
    assert d[c, c, c] == np.float32(0.2)
    # the head is longer along y (b = 0.92) than along x (a = 0.69)
    assert (d[c, :, c] > 0).sum() > (d[c, c, :] > 0).sum()


def test_shepp_logan_matches_phantom3d_algorithm():
    """A literal transcription of Schabel's phantom3d loop (rotate coords, test, add)."""
    from clwave.io.phantoms import SHEPP_LOGAN
    n = 24
    u = (np.arange(n) - (n - 1) / 2) * (2 / n)
    z, y, x = np.meshgrid(u, u, u, indexing="ij")
    coord = np.stack([x.ravel(), y.ravel(), z.ravel()])
    p = np.zeros(coord.shape[1])
    for A, a, b, c, x0, y0, z0, phi, theta, psi in SHEPP_LOGAN:
        phi, theta, psi = np.radians([phi, theta, psi])
        cphi, sphi, cth, sth, cpsi, spsi = (np.cos(phi), np.sin(phi), np.cos(theta),
                                            np.sin(theta), np.cos(psi), np.sin(psi))
        alpha = np.array([[cpsi * cphi - cth * sphi * spsi, cpsi * sphi + cth * cphi * spsi, spsi * sth],
                          [-spsi * cphi - cth * sphi * cpsi, -spsi * sphi + cth * cphi * cpsi, cpsi * sth],
                          [sth * sphi, -sth * cphi, cth]])
        cp = alpha @ coord
        inside = (cp[0] - x0) ** 2 / a ** 2 + (cp[1] - y0) ** 2 / b ** 2 + (cp[2] - z0) ** 2 / c ** 2 <= 1
        p[inside] += A
    ref = p.reshape(n, n, n)
    np.testing.assert_allclose(phantom("shepp-logan", n).data, ref, atol=1e-6)
    assert SHEPP_LOGAN.shape == (10, 10)


@pytest.mark.parametrize("bad, match", [
    (("sphere", 8), "hydrogen, marschner-lobb, shepp-logan"),
    ((None, 8), "phantom name"),
    (("hydrogen", 1), "n must be an integer >= 2"),
    (("hydrogen", 0), "n must be an integer >= 2"),
    (("hydrogen", 8.0), "n must be an integer >= 2"),
    (("hydrogen", "8"), "n must be an integer >= 2"),
    (("hydrogen", True), "n must be an integer >= 2"),
])
def test_invalid_arguments(bad, match):
    for fn in (phantom, analytic):
        with pytest.raises(InputError, match=match) as err:
            fn(*bad)
        assert "\n" not in str(err.value)


def test_invalid_points():
    with pytest.raises(InputError, match=r"\(N, 3\)"):
        analytic("hydrogen", 8)(np.zeros((4, 2)))


def test_name_spelling_is_forgiving():
    np.testing.assert_array_equal(phantom("Marschner_Lobb", 6).data, phantom("marschner-lobb", 6).data)
    assert analytic("marschner-lobb", 16)(np.zeros((2, 3))).shape == (2,)
    assert phantom("hydrogen", np.int64(6)).shape == (6, 6, 6)


def test_garbage_points_are_input_errors():
    with pytest.raises(InputError, match="points"):
        analytic("shepp-logan", 8)([["a", "b", "c"]])
