"""Cone-beam geometry (docs/coordinates.md §5): projection matrices, pixel maps, conversions, bad geometry."""

import numpy as np
import pytest

from clwave.errors import InputError
from clwave.model.camera import Camera
from clwave.model.conebeam import ConeBeam
from clwave.model.volume import Volume

VOL = Volume(np.zeros((6, 8, 10)), spacing=(2.0, 1.0, 0.5), origin=(1.0, -2.0, 3.0))


def _ray_hits(view, points):
    """Independent pixel map: intersect the ray source -> point with the detector plane (NumPy, float64)."""
    cb_u, cb_v = view.u, view.v
    d = points - view.eye
    depth = -(d @ view.n)
    a, b = d @ cb_u / depth, d @ cb_v / depth  # slopes, i.e. detector mm / dsd
    H, W = view.size
    return np.stack([(a - view.principal[0]) / view.slope[0] + W / 2 - 0.5,
                     H / 2 - 0.5 - (b - view.principal[1]) / view.slope[1]], -1)


GEOMETRIES = [
    dict(dso=100.0, dsd=150.0, size=(12, 16), pixel=1.5),
    dict(dso=80.0, dsd=200.0, size=(10, 7), pixel=(2.0, 1.25), offset=(3.0, -4.5), azimuth=30, elevation=20,
         roll=10, isocentre=(1.0, -2.0, 3.5)),
    dict(dso=60.0, dsd=60.0, size=9, pixel=0.7, azimuth=-120, elevation=-35),
]


@pytest.mark.parametrize("kw", GEOMETRIES)
def test_matrix_round_trip_and_projection(kw):
    cb = ConeBeam(**kw)
    P = cb.matrix()
    back = ConeBeam.from_matrix(P, cb.size, isocentre=cb.isocentre)
    assert np.allclose(back.matrix(), P, rtol=1e-12, atol=1e-9)
    assert back.dso == pytest.approx(cb.dso) and np.allclose(back.source, cb.source)
    for scale in (1.0, -3.0):  # a projection matrix is defined up to scale, sign included
        assert np.allclose(ConeBeam.from_matrix(scale * P, cb.size).matrix(), P, atol=1e-9)
    rng = np.random.default_rng(1)
    pts = cb.isocentre + rng.uniform(-5, 5, (20, 3))
    view = cb.view(VOL)
    hom = np.hstack([pts, np.ones((20, 1))]) @ P.T
    assert np.allclose(hom[:, :2] / hom[:, 2:], view.to_pixels(pts), atol=1e-9)
    assert np.allclose(view.to_pixels(pts), _ray_hits(view, pts), atol=1e-9)
    assert np.allclose(hom[:, 2], view.depth(pts))


def test_detector_layout():
    # source on +x: the detector's u is +y (columns right) and v is +z (rows go down, against v)
    cb = ConeBeam(100.0, 150.0, (4, 6), pixel=3.0, offset=(6.0, 0.0))
    view = cb.view(VOL)
    assert cb.source.tolist() == [100.0, 0.0, 0.0] and view.u.tolist() == [0, 1, 0] and view.v.tolist() == [0, 0, 1]
    # the detector point (a, b) mm from the principal point: pixel centre (c + 0.5 - W/2) 3 + 6 along u
    s = view.slopes()
    assert s[0, 0] == pytest.approx([((0.5 - 3) * 3 + 6) / 150, (2 - 0.5) * 3 / 150])
    assert np.allclose(np.linalg.norm(view.rays(), axis=-1), 1)
    assert view.obliquity()[0, 0] == pytest.approx(np.sqrt(1 + np.sum(s[0, 0] ** 2)))


def test_perspective_camera_is_a_centred_cone_beam():
    view = Camera(30, 20, (8, 12), perspective=True, fov=20, distance=50).view(VOL)
    s = view.slopes()
    assert np.arctan(-s[0, 0, 1]) == pytest.approx(-np.radians(10) * (1 - 1 / 8), rel=2e-2)  # near the top edge
    assert s[0, 0, 1] == pytest.approx(np.tan(np.radians(10)) * 7 / 8)
    pts = np.array([[1.0, 2.0, 3.0], [-2.0, 0.5, 1.0]])
    assert np.allclose(view.to_pixels(pts), _ray_hits(view, pts))


@pytest.mark.parametrize("make, words", [
    (lambda: ConeBeam(100, -10, 8), "behind the source"),
    (lambda: ConeBeam(0, 10, 8), "dso"),
    (lambda: ConeBeam(100, 150, 8, pixel=0), "pixel"),
    (lambda: ConeBeam(100, 150, 8, offset=(1, float("nan"))), "offset"),
    (lambda: ConeBeam(float("inf"), 150, 8), "dso"),
    (lambda: ConeBeam(2, 150, 8).view(VOL), "inside the volume"),
    (lambda: ConeBeam(100, 150, 8, isocentre=(-300.0, 0, 0)).view(VOL), "behind the X-ray source"),
    (lambda: ConeBeam.from_matrix(np.full((3, 4), np.nan), 8), "finite"),
    (lambda: ConeBeam.from_matrix(np.zeros((3, 4)), 8), "singular"),
    (lambda: ConeBeam.from_matrix(np.eye(3), 8), "3 x 4"),
    (lambda: ConeBeam.from_matrix(np.array([[1, 0.5, 0, 0], [0, 1, 0, 0], [0, 0, 1, 5.0]]), 8), "skewed"),
])
def test_bad_geometry_is_one_line(make, words):
    with pytest.raises(InputError) as err:
        make()
    assert words in str(err.value) and "\n" not in str(err.value)


def test_tigre_round_trip_and_layout():
    geo = dict(DSO=1000.0, DSD=1536.0, nDetector=np.array([6, 8]), dDetector=np.array([0.8, 0.6]),
               offDetector=np.array([2.0, -1.0]), offOrigin=np.array([5.0, 0.0, -3.0]))
    cb = ConeBeam.from_tigre(geo, np.pi / 2, volume_origin=(1.0, 2.0, 3.0))
    # TIGRE: the source starts on +x and turns about z; the volume's centre is offOrigin from the isocentre
    assert np.allclose(cb.source, cb.isocentre + [0.0, 1000.0, 0.0]) and np.allclose(cb.isocentre, [-4.0, 2.0, 6.0])
    # its detector: u along +y at angle 0 (here -x), v along +z, shifted by offDetector from the principal ray
    assert np.allclose(cb.u, [-1, 0, 0]) and np.allclose(cb.v, [0, 0, 1]) and cb.offset == (2.0, -1.0)
    back, angle = cb.to_tigre(volume_origin=(1.0, 2.0, 3.0))
    assert angle == pytest.approx(np.pi / 2)
    for key, value in geo.items():
        assert np.allclose(back[key], value), key
    with pytest.raises(InputError, match="about z"):
        ConeBeam(100, 150, 8, elevation=10).to_tigre()


def test_offset_shifts_the_detector_as_tigres_off_detector_does():
    """``offset`` (30, 20) puts the detector's centre 30 mm along u and 20 up v from the principal point, as TIGRE's
    offDetector moves its detector (its Siddon projector: pixel column 0 at -sDetecU/2 + dDetecU/2 + offDetecU along
    u): a bead at the isocentre, on the principal ray, lands at column 32 - 0.5 - 30 = 1.5 and row 24 - 0.5 + 20 =
    43.5 of the 48 x 64 detector of 1 mm pixels.  The image, splatted, is symmetric about that pixel corner."""
    import clwave

    data = np.zeros((9, 9, 9), np.float32)
    data[3:6, 3:6, 3:6] = 1.0  # a 3 mm bead about the world origin, the isocentre
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), levels=1)
    geo = dict(DSO=1000.0, DSD=1500.0, nDetector=[48, 64], dDetector=[1.0, 1.0], offDetector=[30.0, 20.0])
    for cb in (ConeBeam(1000, 1500, (48, 64), 1.0, azimuth=90, offset=(30, 20)), ConeBeam.from_tigre(geo, np.pi / 2)):
        image = clwave.splat(wv, cb).image[..., 0]
        row, col = np.unravel_index(np.argmax(image), image.shape)
        assert row in (43, 44) and col in (1, 2), (row, col)
        np.testing.assert_allclose(image[40:48, 0:2], image[40:48, 2:4][:, ::-1], rtol=1e-3, atol=1e-3 * image.max())
        np.testing.assert_allclose(image[40:44, 0:4], image[44:48, 0:4][::-1], rtol=1e-3, atol=1e-3 * image.max())
        assert image[:, 8:].max() < 1e-3 * image.max() and image[:36].max() < 1e-3 * image.max()  # nothing at 61.5
        np.testing.assert_allclose(cb.view(wv).to_pixels(np.zeros((1, 3))), [[1.5, 43.5]], atol=1e-9)


def test_diffdrr_principal_point_is_the_offset_turned_along_u():
    """DiffDRR 0.6.1's ``DRR(..., sdd=1020, height=8, width=10, delx=2.0, x0=30, y0=20)`` at its README pose moves
    its pixel centres by +30 mm along its detector's x, world +x here, against its columns (u = -x), and 20 mm up v
    (world +z): offset (-30, 20) at its detector, (-25, 16.67) at the isocentre 850 mm from the source."""
    rows, cols = np.divmod(np.arange(80), 10)
    ray = np.stack([9.0 - 2.0 * cols + 30.0, np.full(80, -170.0), 7.0 - 2.0 * rows + 20.0], 1)
    cb = ConeBeam.from_diffdrr([0.0, 850.0, 0.0], ray, (8, 10))
    assert np.allclose(cb.offset, (-30.0 * 850 / 1020, 20.0 * 850 / 1020))
    np.testing.assert_allclose(cb.view(VOL).to_pixels(np.zeros((1, 3))), [[4.5 + 15, 3.5 + 10]], atol=1e-9)


def test_diffdrr_round_trip_and_layout():
    cb = ConeBeam(700.0, 1100.0, (6, 8), pixel=(0.9, 1.3), offset=(4.0, -2.5), azimuth=35, elevation=-20, roll=15)
    source, target = cb.to_diffdrr()
    back = ConeBeam.from_diffdrr(source, target, (6, 8))
    P, Q = cb.matrix(), back.matrix()
    assert np.allclose(P / np.linalg.norm(P[2, :3]), Q / np.linalg.norm(Q[2, :3]), atol=1e-9)
    assert np.allclose(back.to_diffdrr()[1] - source, (target - source) * cb.dso / cb.dsd)  # its detector: dsd = dso
    # DiffDRR 0.6.1's own rays (DRR(load_example_ct(), sdd=1020, height=128, delx=3.125), pose: no rotation,
    # translation (0, 850, 0), "ZXY" Euler angles; its default reverse_x_axis=True): the source on +y, columns
    # from +x to -x, rows from +z to -z, the detector 170 mm beyond the isocentre
    rows, cols = np.divmod(np.arange(128 * 128), 128)
    ray = np.stack([198.4375 - 3.125 * cols, np.full(128 * 128, -170.0), 198.4375 - 3.125 * rows], 1)
    cb = ConeBeam.from_diffdrr([0.0, 850.0, 0.0], ray, 128)
    assert np.allclose(cb.n, [0, 1, 0]) and np.allclose(cb.u, [-1, 0, 0]) and np.allclose(cb.v, [0, 0, 1])
    assert np.allclose(cb.source, [0, 850, 0]) and np.allclose(cb.slope, 3.125 / 1020) and cb.dso == 850.0
    assert np.allclose(cb.principal, 0.0, atol=1e-12)
    with pytest.raises(InputError, match="mirrored") as err:  # reverse_x_axis=False: columns the other way
        ConeBeam.from_diffdrr([0.0, 850.0, 0.0], ray * [-1, 1, 1], 128)
    assert "\n" not in str(err.value)


def test_slope_grid_covers_every_pixel():
    # the grid is found from each view's first and last rows and columns: it spans exactly the pixels' slopes
    from clwave.splat.perspective import SLOPE_STEP, slope_grid

    views = [ConeBeam(300, 450, (9, 14), pixel=(0.7, 1.1), offset=(3.0, -2.0), roll=25).view(VOL),
             ConeBeam(300, 450, (5, 4), pixel=2.0).view(VOL)]
    lo, step, count = slope_grid(views)
    s = np.concatenate([view.slopes().reshape(-1, 2) for view in views])
    assert np.array_equal(lo, s.min(axis=0)) and np.allclose(lo + step * (count - 1), s.max(axis=0), atol=1e-15)
    assert np.all(step <= SLOPE_STEP) and np.all(count >= 2)


@pytest.mark.parametrize("kw", GEOMETRIES[:2])
def test_mirrored_matrix_named_with_its_fix(kw):
    cb = ConeBeam(**kw)
    P, W = cb.matrix(), cb.size[1]
    mirrored = np.vstack([(W - 1) * P[2] - P[0], P[1:]])  # columns the other way: col -> W - 1 - col
    for scale in (1.0, -2.0):
        with pytest.raises(InputError, match=r"mirrored .*P\[0\] = \(W - 1\) P\[2\] - P\[0\]") as err:
            ConeBeam.from_matrix(scale * mirrored, cb.size).view(VOL)
        assert "\n" not in str(err.value)
    with pytest.raises(InputError, match="mirrored"):  # a reduced frame of it too
        ConeBeam.from_matrix(mirrored, cb.size).reduced(2).view(VOL)
    fixed = np.vstack([(W - 1) * mirrored[2] - mirrored[0], mirrored[1:]])  # the fix the line gives
    assert np.allclose(ConeBeam.from_matrix(fixed, cb.size).view(VOL).to_pixels(VOL.origin),
                       cb.view(VOL).to_pixels(VOL.origin), atol=1e-9)
    with pytest.raises(InputError, match="turn the gantry") as err:  # a gantry facing away is not a matrix's mirror
        ConeBeam(**dict(kw, azimuth=kw.get("azimuth", 0) + 180, isocentre=2 * cb.source - cb.isocentre)).view(VOL)
    assert "mirrored" not in str(err.value)
