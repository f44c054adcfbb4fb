"""A DICOM series' geometry as a radiologist expects it (trial28): a gantry tilt drawn upright in patient space, an
uneven series resampled onto even slices, checked against analytic objects at known patient millimetres
(docs/coordinates.md §1)."""

import warnings

import numpy as np
import pytest
from pydicom.uid import generate_uid

import clwave
from clwave.errors import ClwaveWarning
from test_loaders import write_dicom_slice

CENTRE = np.array([4.0, -6.0, 20.0])  # LPS mm
HALF = np.array([6.0, 4.0, 12.0])  # the box's half sizes (LPS x, y, z), mm


def box_hu(lps):
    """A box of 1000 HU in 0 HU about ``CENTRE`` (``lps``: (..., 3) mm), its faces ramps 3 mm wide (smooth on the
    slices' scale), the 500 HU level on them: 1000 times the product of each axis's ramp."""
    ramp = np.clip((HALF - np.abs(lps - CENTRE)) / 3 + 0.5, 0.0, 1.0)
    return 1000.0 * ramp.prod(axis=-1)


def write_box_series(folder, tilt=0.0, turn=0.0, z=None, pixel=1.0, n=40):
    """Axial slices of :func:`box_hu` through the table positions ``z`` (LPS mm; default every 1.5 mm over 54 mm),
    each slice's plane tilted ``tilt`` degrees about the patient's left-right axis (a gantry tilt: the slices'
    positions stay on a line along the table) and turned ``turn`` degrees about the table's axis; stored + 1024."""
    t, a = np.radians(tilt), np.radians(turn)
    spin = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    row, col = spin @ (1.0, 0.0, 0.0), spin @ (0.0, np.cos(t), -np.sin(t))
    z = CENTRE[2] + 1.5 * (np.arange(37) - 18) if z is None else np.asarray(z, float)
    j, i = np.mgrid[:n, :n] * pixel
    uid = generate_uid()
    folder.mkdir(exist_ok=True)
    for k, zk in enumerate(z):
        corner = np.array([CENTRE[0], CENTRE[1], zk]) - (n - 1) / 2 * pixel * (row + col)
        lps = corner + i[..., None] * row + j[..., None] * col
        write_dicom_slice(folder / f"s{k:02d}", np.round(box_hu(lps) + 1024), corner, uid,
                          orientation=(*row, *col), pixel_spacing=(pixel, pixel), rescale=(1, -1024))
    return folder


def world_points(vol):
    """Each voxel's RAS position (mm), (z, y, x, 3) as ``vol.data``."""
    index = np.stack(np.meshgrid(*[np.arange(n) for n in vol.shape[:3]], indexing="ij"), axis=-1)
    return vol.voxel_to_world(index.reshape(-1, 3).astype(float)).reshape(*vol.shape[:3], 3)


def test_a_gantry_tilt_is_drawn_upright_in_patient_space(tmp_path):
    """A 12 degree tilt (trial28's SE5) resampled straight onto the RAS axes: obliquity 0, spacing each axis's part
    of its source axis (1 mm columns, the table's 1.5 mm, the rows' 1 x cos 12 mm), and the box where the patient's
    millimetres put it: its centroid within a tenth of a millimetre, its voxels of 500 HU or more from its faces
    to a voxel within them."""
    with pytest.warns(ClwaveWarning, match="gantry tilt of 12 degrees") as seen:
        vol = clwave.load(write_box_series(tmp_path, tilt=12.0), progress_bar=False)
    assert not any("oblique" in str(w.message) for w in seen)
    assert vol.obliquity == 0.0
    assert vol.spacing == pytest.approx((1.5, np.cos(np.radians(12)), 1.0))
    ras = world_points(vol)
    weight = vol.data[..., None] - vol.data.min()
    centre = (ras * weight).sum(axis=(0, 1, 2)) / weight.sum()
    np.testing.assert_allclose(centre, CENTRE * (-1, -1, 1), atol=0.1)
    inside = ras[vol.data >= 500]
    spacing = np.array(vol.spacing[::-1])
    assert np.all(np.abs(inside.min(axis=0) - (CENTRE * (-1, -1, 1) - HALF)) <= spacing)
    assert np.all(np.abs(inside.max(axis=0) - (CENTRE * (-1, -1, 1) + HALF)) <= spacing)


def test_a_tilted_series_renders_the_lateral_view_of_the_untilted_one(tmp_path):
    """The same box scanned straight and with a 12 degree tilt: their lateral X-rays (from the patient's right)
    agree within 8 % of their peak at any pixel (the one linear interpolation of the tilt, at the box's faces) and
    0.5 % on average; the tilt drawn in its own axes (until trial28) turned the box 12 degrees, 58 % of the peak."""
    images = []
    for tilt in (0.0, 12.0):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ClwaveWarning)
            vol = clwave.load(write_box_series(tmp_path / f"t{tilt:g}", tilt=tilt), progress_bar=False)
        wv = clwave.WaveletVolume.from_volume(vol, levels=1)
        camera = clwave.Camera(0, 0, size=32, target=tuple(CENTRE * (-1, -1, 1)), extent=48.0)
        images.append(clwave.splat(wv, camera).image[..., 0])
    straight, tilted = images
    assert straight.max() == pytest.approx(12000, rel=0.05)  # 12 mm of box at 1000 HU across it
    assert np.abs(tilted - straight).max() <= 0.08 * straight.max()
    assert np.abs(tilted - straight).mean() <= 0.005 * straight.max()


def test_a_tilted_series_missing_a_slice_is_placed_as_the_complete_one(tmp_path):
    """The tilted box of :func:`test_a_gantry_tilt_is_drawn_upright_in_patient_space` with the slice through its
    centre removed: resampled along the normal onto the complete series' 37 slices (1.5 cos 12 mm apart), then
    straight, its centroid within a tenth of a millimetre."""
    z = np.delete(CENTRE[2] + 1.5 * (np.arange(37) - 18), 18)
    with pytest.warns(ClwaveWarning, match="resampled onto 37 even slices 1.467 mm apart"):
        vol = clwave.load(write_box_series(tmp_path, tilt=12.0, z=z), progress_bar=False)
    assert vol.obliquity == 0.0 and vol.spacing == pytest.approx((1.5, np.cos(np.radians(12)), 1.0))
    weight = vol.data[..., None] - vol.data.min()
    centre = (world_points(vol) * weight).sum(axis=(0, 1, 2)) / weight.sum()
    np.testing.assert_allclose(centre, CENTRE * (-1, -1, 1), atol=0.1)


@pytest.mark.parametrize("turn", [0.0, 20.0, -7.5])
def test_a_double_oblique_tilt_keeps_the_obliquity_left(tmp_path, turn):
    """A series turned ``turn`` degrees about the table's axis as well as tilted 12 degrees: the tilt undone, the
    turn kept as the volume's obliquity (with the oblique warning where it is one)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ClwaveWarning)
        vol = clwave.load(write_box_series(tmp_path, tilt=12.0, turn=turn, n=24), progress_bar=False)
    assert vol.obliquity == pytest.approx(abs(turn), abs=0.01)


def bowl(lps):
    """HU quadratic along z and linear across (stored + 1024 as whole numbers where ``lps`` are whole mm)."""
    return 2 * lps[..., 0] - lps[..., 1] + lps[..., 2] ** 2


@pytest.mark.parametrize("z, spacing, words", [
    # one slice missing (trial28's SE4): 10 mm
    ((0, 2, 4, 6, 8, 12, 14, 16), 2.0, "gaps are 2 mm from 0 to 8 mm, 4 mm from 8 to 12 mm, 2 mm from 12 to 16 mm"),
    # two spacings (SE6): 2 mm below 6 mm, 4 mm above
    ((-4, -2, 0, 2, 4, 6, 10, 14, 18), 2.0, "gaps are 2 mm from -4 to 6 mm, 4 mm from 6 to 18 mm"),
    # two missing in a row, 3 of the smallest
    ((0, 3, 6, 15, 18), 3.0, "gaps are 3 mm from 0 to 6 mm, 9 mm from 6 to 15 mm, 3 mm from 15 to 18 mm"),
])
def test_an_uneven_series_is_resampled_onto_even_slices(tmp_path, z, spacing, words):
    """Slices of :func:`bowl` at ``z``: loaded onto slices ``spacing`` apart from the first to the last, with a
    warning naming the gaps and where; the slices that exist unchanged, those between them the linear interpolation
    of their neighbours' analytic values (not the bowl's own: nothing is invented)."""
    uid, z = generate_uid(), np.asarray(z, float)
    j, i = np.mgrid[:6, :5].astype(float)
    for k, zk in enumerate(z):
        lps = np.stack([-20 + i, 30 + j, np.full_like(i, zk)], axis=-1)
        write_dicom_slice(tmp_path / f"s{k}", bowl(lps) + 1024, (-20, 30, zk), uid, pixel_spacing=(1, 1),
                          rescale=(1, -1024))
    with pytest.warns(ClwaveWarning, match=f"is not evenly spaced: its slice {words} along the normal; resampled "
                                           f"onto {int(np.ptp(z) / spacing) + 1} even slices {spacing:g} mm apart"):
        vol = clwave.load(tmp_path, progress_bar=False)
    assert vol.spacing == pytest.approx((spacing, 1.0, 1.0)) and vol.origin[2] == pytest.approx((z[0] + z[-1]) / 2)
    even = z[0] + spacing * np.arange(vol.shape[0])
    for n, zn in enumerate(even):
        lps = np.stack([-20 + i, 30 + j, np.full_like(i, zn)], axis=-1)
        below, above = z[z <= zn].max(), z[z >= zn].min()
        w = 0.0 if above == below else (zn - below) / (above - below)
        expected = (1 - w) * bowl(lps.copy() * (1, 1, 0) + (0, 0, below)) + w * bowl(lps * (1, 1, 0) + (0, 0, above))
        np.testing.assert_allclose(vol.data[n], expected[::-1, ::-1], rtol=0, atol=1e-3)  # RAS: rows, columns flipped
        if zn in z:
            assert np.array_equal(vol.data[n], bowl(lps)[::-1, ::-1].astype(np.float32))
