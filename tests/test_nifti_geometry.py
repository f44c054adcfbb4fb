"""A NIfTI file's geometry as a neuroimaging user meets it (trial22): a sheared affine resampled onto a straight grid,
a file without orientation warned of, and what ``clwave info`` says of the codes, the forms, the shear and the
scaling (docs/coordinates.md §1)."""

import nibabel as nib
import numpy as np
import pytest

import clwave
from clwave.errors import ClwaveWarning
from test_cli import run


def _save(path, data_ijk, affine, sform=2, qform=0):
    image = nib.Nifti1Image(data_ijk, None)
    image.set_sform(affine, code=sform)
    image.set_qform(None if qform == 0 else affine, code=qform)
    nib.save(image, path)
    return path


@pytest.mark.parametrize("slope", [1, -1])
def test_a_sheared_affine_of_whole_voxel_shifts_is_its_voxels_moved(tmp_path, slope):
    """Each slice k shifted by ``slope * k`` whole voxels along i (dcm2niix's uncorrected gantry tilt, column 3 of
    the affine leaning along x): the straight grid holds every voxel unchanged at ``i + slope * k`` (shifted to start
    at 0), what no slice covers at the volume's least value; spacing the columns' straight parts (2, 3, 2 mm), the
    centre where the affine puts the straight grid's."""
    rng = np.random.default_rng(1)
    ni, nj, nk = 5, 4, 6
    data = rng.uniform(1, 2, (ni, nj, nk)).astype(np.float32)
    affine = np.array([[2.0, 0, 2 * slope, -10], [0, 3, 0, 5], [0, 0, 2, 7], [0, 0, 0, 1]])
    path = _save(tmp_path / "sheared.nii", data, affine)
    expected = np.full((ni + nk - 1, nj, nk), data.min(), np.float32)
    start = 0 if slope > 0 else nk - 1
    for k in range(nk):
        expected[start + slope * k + np.arange(ni), :, k] = data[:, :, k]
    with pytest.warns(ClwaveWarning, match="affine is sheared 45 degrees .*resampled onto a straight grid"):
        vol = clwave.load(path)
    np.testing.assert_array_equal(vol.data, expected.transpose(2, 1, 0))
    assert vol.spacing == (2.0, 3.0, 2.0) and vol.obliquity == 0.0
    corner = -10 + 2 * (0 if slope > 0 else -(nk - 1))  # the straight grid's first x
    np.testing.assert_allclose(vol.origin, (corner + 2 * (ni + nk - 2) / 2, 5 + 3 * 1.5, 7 + 2 * 2.5))


def test_a_sheared_affine_resampled_holds_a_linear_function_of_the_world_exactly(tmp_path):
    """Shears in every plane (i along j and k, j along k; fractions of a voxel): voxels sampling a linear function
    of the world hold it after the resampling, wherever the sheared grid covers the straight voxel (linear
    interpolation is exact for it), at the straight voxels' own world positions."""
    def f(x, y, z):
        return 0.3 * x - 0.2 * y + 0.5 * z + 40

    ni, nj, nk = 9, 8, 7
    affine = np.array([[1.5, 0.4, -0.7, 3], [0, 2.0, 0.5, -4], [0, 0, 2.5, 1], [0, 0, 0, 1]])
    i, j, k = np.meshgrid(np.arange(ni), np.arange(nj), np.arange(nk), indexing="ij")
    world = np.einsum("ab,bijk->aijk", affine[:3, :3], np.array([i, j, k])) + affine[:3, 3, None, None, None]
    path = _save(tmp_path / "linear.nii", f(*world).astype(np.float32), affine)
    with pytest.warns(ClwaveWarning, match="sheared"):
        vol = clwave.load(path)
    z, y, x = np.meshgrid(*[np.arange(n) for n in vol.shape], indexing="ij")
    points = vol.voxel_to_world(np.column_stack([z.ravel(), y.ravel(), x.ravel()]).astype(float))
    inside = np.linalg.solve(affine[:3, :3], (points - affine[:3, 3]).T).T  # the sheared grid's index of each
    covered = np.all((inside >= -1e-9) & (inside <= np.array([ni, nj, nk]) - 1 + 1e-9), axis=1)
    assert covered.sum() > 0.3 * ni * nj * nk
    np.testing.assert_allclose(vol.data.ravel()[covered], f(*points[covered].T), rtol=0, atol=2e-5 * 60)
    assert vol.spacing == (2.5, 2.0, 1.5)


def test_an_affine_sheared_by_float32_rounding_alone_is_no_shear(tmp_path):
    """An sform stored in float32 (NIfTI-1) rounds an oblique affine's columns off right angles by about 1e-7:
    under a tenth of a voxel over the grid, so no resampling and no warning of a shear."""
    rotation = np.array([[np.cos(0.3), -np.sin(0.3), 0], [np.sin(0.3), np.cos(0.3), 0], [0, 0, 1]])
    affine = np.eye(4)
    affine[:3, :3] = rotation * 1.7
    path = _save(tmp_path / "oblique.nii", np.ones((6, 5, 4), np.float32), affine)
    with pytest.warns(ClwaveWarning) as seen:
        vol = clwave.load(path)
    assert vol.shape == (4, 5, 6) and not any("sheared" in str(w.message) for w in seen)


def test_info_tells_a_shear_apart_from_obliquity(tmp_path, capsys):
    sheared = _save(tmp_path / "sheared.nii", np.ones((5, 4, 6), np.float32),
                    np.array([[2.0, 0, 2, 0], [0, 3, 0, 0], [0, 0, 2, 0], [0, 0, 0, 1]]))
    code, out, err = run(capsys, "info", str(sheared))
    lines = {line.split()[0]: line for line in out.splitlines()}
    assert code == 0 and "oblique" not in lines, out
    assert "45.00 degrees (its axes not at right angles" in lines["sheared"]
    assert "sheared grid resampled onto a straight one" in lines["stored"]
    oblique = np.eye(4)
    oblique[:3, :3] = [[np.cos(0.3), -np.sin(0.3), 0], [np.sin(0.3), np.cos(0.3), 0], [0, 0, 1]]
    code, out, err = run(capsys, "info", str(_save(tmp_path / "oblique.nii", np.ones((5, 4, 6), np.float32), oblique)))
    lines = {line.split()[0]: line for line in out.splitlines()}
    assert code == 0 and "sheared" not in lines and "17.19 degrees" in lines["oblique"], out


def test_info_of_a_singular_affine_is_the_readers_one_line(tmp_path, capsys):
    singular = np.eye(4)
    singular[:3, 2] = singular[:3, 0]  # two axes along one direction: no place for the voxels
    path = _save(tmp_path / "singular.nii", np.ones((5, 4, 6), np.float32), singular)
    for command in ("info", "render"):
        code, out, err = run(capsys, command, str(path), *(("-o", str(tmp_path / "x.png")) if command == "render"
                                                            else ()))
        assert code == 2 and "not finite or not invertible" in err and len(err.strip().splitlines()) == 1, err


@pytest.mark.parametrize("shear, words", [
    (1e5, "the straight grid that holds it is 300005 x 4 x 6 voxels (i, j, k: the file's axes), which needs about"),
    (1e18, "voxels (i, j, k: the file's axes), more than an array holds")])
def test_a_shear_whose_straight_grid_does_not_fit_is_named_as_the_shear(tmp_path, capsys, monkeypatch, shear, words):
    """A shear of 1e5 voxels a voxel makes a straight grid of 300005 x 4 x 6 voxels: refused naming the shear, not
    with the hint of reading in chunks (a sheared file is read whole); one of 1e18 a grid past any array, which
    ``info`` described as a corrupt file (numpy's 'iterator is too large' from the stand-in it placed) (refuzz22).
    1e18, not 1e12: a float32 sform keeps it (as srow_x's 1e12 of two axes in the fuzz case)."""
    import clwave.device.memory as memory

    monkeypatch.setattr(memory, "available_bytes", lambda: 1 << 24)  # 16 MiB: the grid of 1e5 needs more
    affine = np.eye(4)
    affine[0, 1] = shear
    path = _save(tmp_path / "sheared.nii", np.ones((5, 4, 6), np.float32), affine)
    for command in ("info", "compress")[shear < 1e6:]:  # info describes a grid that an array holds
        code, out, err = run(capsys, command, str(path), *(("-o", str(tmp_path / "x.clw")) if command == "compress"
                                                            else ()))
        assert code == 2 and "sheared.nii's affine is sheared 90 degrees: " in err and words in err, err
        assert "fix the affine" in err and "chunk" not in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "x.clw").exists()


def test_a_file_without_orientation_is_warned_of_and_info_says_what_was_assumed(tmp_path, capsys):
    path = _save(tmp_path / "none.nii", np.ones((4, 3, 2), np.float32), np.diag([2.0, 2, 2, 1]), sform=0)
    with pytest.warns(ClwaveWarning, match="has no orientation .*sform_code and qform_code are 0.*LAS") as seen:
        clwave.load(path)
    assert sum("no orientation" in str(w.message) for w in seen) == 1
    code, out, err = run(capsys, "info", str(path))
    assert code == 0 and "orient     none in the file (sform_code 0, qform_code 0): nibabel's fallback, LAS, " \
                         "assumed" in out, out
    assert err.count("no orientation") == 1


def test_info_names_the_codes_the_form_used_where_they_differ_and_the_scaling(tmp_path, capsys):
    image = nib.Nifti1Image(np.arange(24, dtype=np.int16).reshape(4, 3, 2), None)
    image.set_qform(np.diag([-2.0, 2, 2, 1]), code=1)  # LAS
    image.set_sform(np.diag([2.0, 2, 2, 1]), code=2)   # RAS: nibabel uses the sform
    image.header.set_slope_inter(4.0, -10.0)
    nib.save(image, tmp_path / "both.nii.gz")
    code, out, err = run(capsys, "info", str(tmp_path / "both.nii.gz"))
    lines = {line.split()[0]: line for line in out.splitlines()}
    assert code == 0, err
    assert lines["orient"].endswith("stored RAS, from the sform (nibabel's choice; sform_code 2, qform_code 1); the "
                                    "qform differs")
    assert lines["scaled"].endswith("scl_slope 4, scl_inter -10 (applied as read)")
    nib.save(nib.Nifti1Image(np.ones((4, 3, 2), np.float32), np.diag([-1.0, 1, 1, 1])), tmp_path / "las.nii")
    code, out, err = run(capsys, "info", str(tmp_path / "las.nii"))
    assert "stored LAS, from the sform (nibabel's choice; sform_code 2, qform_code 0)\n" in out and "differs" not in out
    assert "scaled" not in out


def test_a_tilt_dcm2niix_left_in_the_affine_comes_out_upright(tmp_path):
    """dcm2niix's uncorrected 12 degree gantry tilt: rows along x, columns tilted in the y-z plane, the slices'
    step along the table (z). Resampled straight onto the RAS axes (obliquity 0), spacing each axis's part of its
    column (1, 1.5, cos 12 mm); a linear function of the world held exactly where the sheared grid covers."""
    def f(x, y, z):
        return 0.3 * x - 0.2 * y + 0.5 * z + 40

    t = np.radians(12)
    affine = np.array([[1.0, 0, 0, -4], [0, np.cos(t), 0, 3], [0, np.sin(t), 1.5, 1], [0, 0, 0, 1]])
    i, j, k = np.meshgrid(np.arange(10), np.arange(12), np.arange(8), indexing="ij")
    world = np.einsum("ab,bijk->aijk", affine[:3, :3], np.array([i, j, k])) + affine[:3, 3, None, None, None]
    with pytest.warns(ClwaveWarning, match="affine is sheared 12 degrees") as seen:
        vol = clwave.load(_save(tmp_path / "tilt.nii", f(*world).astype(np.float32), affine))
    assert vol.obliquity == 0.0 and not any("oblique" in str(w.message) for w in seen)
    assert vol.spacing == pytest.approx((1.5, np.cos(t), 1.0))
    z, y, x = np.meshgrid(*[np.arange(n) for n in vol.shape], indexing="ij")
    points = vol.voxel_to_world(np.column_stack([z.ravel(), y.ravel(), x.ravel()]).astype(float))
    inside = np.linalg.solve(affine[:3, :3], (points - affine[:3, 3]).T).T
    covered = np.all((inside >= -1e-9) & (inside <= np.array([9, 11, 7]) + 1e-9), axis=1)
    assert covered.sum() > 0.5 * 10 * 12 * 8
    np.testing.assert_allclose(vol.data.ravel()[covered], f(*points[covered].T), rtol=0, atol=2e-5 * 60)
