"""Named anatomical views of a RAS volume (trial28's M5; docs/coordinates.md §2): each puts markers at known patient
positions where radiographs and CT slices show them."""

import numpy as np
import pytest

import clwave
from clwave.errors import InputError
from test_cli import run

MARKERS = {"L": (-8.0, 0.0, 0.0), "A": (0.0, 8.0, 0.0), "S": (0.0, 0.0, 8.0)}  # RAS mm: patient's left, front, top
# (right, up) in the image, mm from its centre, of each marker: the radiological conventions, written out by hand
EXPECTED = {
    "anterior": dict(L=(8, 0), A=(0, 0), S=(0, 8)),    # AP: the patient's left on the image's right, head up
    "posterior": dict(L=(-8, 0), A=(0, 0), S=(0, 8)),  # PA: their left on the left
    "left": dict(L=(0, 0), A=(-8, 0), S=(0, 8)),       # left lateral: anterior on the image's left
    "right": dict(L=(0, 0), A=(8, 0), S=(0, 8)),
    "inferior": dict(L=(8, 0), A=(0, 8), S=(0, 0)),    # as CT slices are shown: anterior up, left on the right
    "superior": dict(L=(-8, 0), A=(0, 8), S=(0, 0)),
}


@pytest.fixture(scope="module")
def markers():
    """A 33^3 volume of 1 mm voxels centred at 0, a Gaussian blob (sigma 1.5 mm) at each marker, one a channel."""
    z, y, x = np.mgrid[:33, :33, :33] - 16.0
    blobs = [np.exp(-((x - p[0]) ** 2 + (y - p[1]) ** 2 + (z - p[2]) ** 2) / (2 * 1.5 ** 2)) for p in MARKERS.values()]
    return clwave.WaveletVolume.from_volume(clwave.Volume(np.stack(blobs, axis=-1).astype(np.float32)), levels=1)


@pytest.mark.parametrize("name", EXPECTED)
def test_each_named_view_puts_the_markers_where_the_convention_says(markers, name):
    camera = clwave.Camera(**clwave.named_view(name), size=33, target=(0, 0, 0), extent=33.0)
    image = clwave.splat(markers, camera).image
    rows, columns = np.mgrid[:33, :33]
    for c, marker in enumerate(MARKERS):
        weight = np.clip(image[..., c], 0, None)
        right = ((columns - 16) * weight).sum() / weight.sum()
        up = ((16 - rows) * weight).sum() / weight.sum()
        np.testing.assert_allclose((right, up), EXPECTED[name][marker], atol=0.25, err_msg=f"{name}: {marker}")


def test_an_unknown_view_is_named_with_the_choices():
    with pytest.raises(InputError, match=r"^unknown view 'front'; choose one of anterior, posterior, left, right, "
                                         r"superior, inferior \(a RAS\+ volume's sides\)$"):
        clwave.named_view("front")


def test_view_on_the_command_line(tmp_path, capsys):
    """``--view left`` draws what ``--azimuth 180 --elevation 0`` draws; beside either angle it is refused in one
    line; ``drr --view anterior`` is the pose table's azimuth 90, elevation 0."""
    volume = tmp_path / "v.npy"
    z, y, x = np.mgrid[:12, :10, :8]
    np.save(volume, ((x < 3) * 1.0 + (z > 8) * 2.0 + (y > 6) * 0.5).astype(np.float32))
    common = [str(volume), "--size", "16", "--levels", "1", "--keep", "1"]
    for name, angles in (("a", ["--view", "left"]), ("b", ["--azimuth", "180", "--elevation", "0"])):
        output = ["-o", str(tmp_path / f"{name}.png"), "--raw", str(tmp_path / f"{name}.npy")]
        assert run(capsys, "render", *common, *angles, *output)[0] == 0
    np.testing.assert_array_equal(np.load(tmp_path / "a.npy"), np.load(tmp_path / "b.npy"))
    code, out, err = run(capsys, "render", *common, "--view", "left", "--elevation", "5", "-o", str(tmp_path / "c.png"))
    assert code == 2 and err.strip() == "clwave: error: --view left sets the azimuth and elevation that --elevation " \
                                        "sets: give one or the other"
    table = tmp_path / "ap.csv"
    table.write_text("azimuth,elevation\n90,0\n")
    drr = ["drr", str(volume), "--size", "12", "--dso", "60", "--dsd", "90", "--levels", "1", "--keep", "1"]
    assert run(capsys, *drr, "--view", "anterior", "-o", str(tmp_path / "d.npy"))[0] == 0
    assert run(capsys, *drr, "--poses", str(table), "-o", str(tmp_path / "e.npy"))[0] == 0
    np.testing.assert_array_equal(np.load(tmp_path / "d.npy"), np.load(tmp_path / "e.npy"))
    code, out, err = run(capsys, *drr, "-o", str(tmp_path / "f.npy"))
    assert code == 2 and "give --poses TABLE (a pose a row) or --view NAME" in err
