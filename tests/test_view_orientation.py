"""The viewer's orientation letters and standard views (docs/viewer.md §4, "Orientation"): a marker voxel placed at a
patient's side in the file's own axes (a NIfTI with a negative, permuted x step; an LPS DICOM series) appears, in the
frame the page draws, towards the edge whose label names that side; in orthographic and perspective views, zoomed;
a volume with no patient axes is labelled by its world axes; the hello's views are geometry.VIEWS."""

import numpy as np
import pytest

import clwave
from clwave.model.camera import Camera
from clwave.model.geometry import VIEWS, named_view
from clwave.splat.renderer import SplatRenderer
from clwave.view.export import Origin
from clwave.view.frames import ViewState, XraySource
from clwave.view.orientation import edges, letters, patient_world
from test_loaders import write_dicom_slice
from test_view import decode

N, SIZE, OFF = 12, (40, 56), 4  # voxels a side, the image, the marker's voxels from the centre
#: a patient's sides as RAS+ directions, and the opposite letter
SIDES = {"L": ((-1, 0, 0), "R"), "A": ((0, 1, 0), "P"), "S": ((0, 0, 1), "I")}
#: the edges of each named view, written out from the radiological conventions (docs/coordinates.md §2's table)
NAMED = {"anterior": dict(left="R", right="L", top="S", bottom="I"),
         "posterior": dict(left="L", right="R", top="S", bottom="I"),
         "left": dict(left="A", right="P", top="S", bottom="I"),
         "right": dict(left="P", right="A", top="S", bottom="I"),
         "inferior": dict(left="R", right="L", top="A", bottom="P"),
         "superior": dict(left="L", right="R", top="A", bottom="P")}
#: (azimuth, elevation, zoom, fov): the named views, and oblique ones, zoomed, in perspective
VIEWS_SEEN = [(*VIEWS[name], 1.0, None) for name in VIEWS] + [
    (30.0, 20.0, 1.5, 40.0), (200.0, -50.0, 1.5, None), (300.0, 60.0, 1.0, 30.0)]


def cube(index) -> np.ndarray:
    """N^3 of 10 (so the content, and the view's target, is the whole box) with 4000 in the 3^3 voxels about
    ``index``."""
    data = np.full((N, N, N), 10, np.uint16)
    i, j, k = index
    data[i - 1:i + 2, j - 1:j + 2, k - 1:k + 2] = 4000
    return data


def nifti(path, side):
    """A NIfTI whose axes are the patient's posterior, superior and left (a negative x step, permuted: PSL), the
    marker OFF voxels towards ``side`` by the file's own affine."""
    import nibabel as nib

    turn = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])  # columns: i -> P, j -> S, k -> L
    index = (N // 2 + turn.T @ (OFF * np.array(SIDES[side][0]))).round().astype(int)
    affine = np.eye(4)
    affine[:3, :3] = turn
    nib.save(nib.Nifti1Image(cube(index), affine), path)
    return path


def dicom(folder, side):
    """A coronal LPS DICOM series (rows along the patient's left, columns down, slices posterior), the marker OFF
    voxels towards ``side``: along a row to the left, up the column to the top, back through the slices to the front."""
    folder.mkdir()
    k, r, c = N // 2 + OFF * np.array(dict(L=(0, 0, 1), S=(0, -1, 0), A=(-1, 0, 0))[side])
    data = cube((k, r, c))
    for s in range(N):
        write_dicom_slice(folder / f"{s}.dcm", data[s], (0.0, float(s), 0.0), "1.2.3", orientation=(1, 0, 0, 0, 0, -1),
                          pixel_spacing=(1.0, 1.0), rescale=(1, 0), number=1)
    return folder


def source(wv, patient):
    xray = XraySource(wv, SIZE, SplatRenderer(wv))
    xray.patient = patient
    return xray


def final(xray, azimuth, elevation, zoom, fov):
    state = ViewState(seq=1, azimuth=azimuth, elevation=elevation, zoom=zoom, mode="xray", detail=1.0,
                      window=(0.0, 20000.0), moving=False, background=0.0, shading=True, fov=fov)
    *_, frame = xray.frames(state, xray.pacing())
    assert frame.figures["final"]
    return frame


def marker_offset(frame):
    """(right, up) of the marker's centroid from the image's centre, pixels."""
    grey = decode(frame.data).astype(float)
    grey = grey if grey.ndim == 2 else grey[..., 0]
    rows, columns = np.nonzero(grey >= 128)
    assert rows.size, "the marker is in the image"
    H, W = grey.shape
    return columns.mean() - (W - 1) / 2, (H - 1) / 2 - rows.mean()


def check_marker(frame, letter, opposite):
    """Every edge whose label names the marker's side has the marker towards it; the opposite side's, away; how many
    edges named either."""
    right, up = marker_offset(frame)
    toward = dict(left=-right, right=right, top=up, bottom=-up)
    named = 0
    for edge, label in frame.figures["orientation"].items():
        if letter in label:
            assert toward[edge] > 2, (edge, label, letter, toward)
            named += 1
        if opposite in label:
            assert toward[edge] < -2, (edge, label, letter, toward)
            named += 1
    return named


@pytest.mark.parametrize("kind", ["nifti", "dicom"])
def test_a_marker_at_a_patients_side_appears_at_the_edge_labelled_so(tmp_path, kind):
    """For a NIfTI stored PSL and a coronal LPS DICOM series, in 9 views (the six named, obliques, zoomed,
    perspective): the markers at the patient's left, front and top lie towards every edge named L, A, S and away from
    every edge named R, P, I; each named view's edges are those of the radiological table."""
    for side, ((_, opposite)) in SIDES.items():
        path = (nifti if kind == "nifti" else dicom)(tmp_path / f"{side}{'.nii' if kind == 'nifti' else ''}", side)
        wv = clwave.WaveletVolume.from_volume(clwave.load(path, progress_bar=False), levels=1)
        assert patient_world(wv, Origin())
        xray = source(wv, patient=True)
        named = 0
        for azimuth, elevation, zoom, fov in VIEWS_SEEN:
            frame = final(xray, azimuth, elevation, zoom, fov)
            named += check_marker(frame, side, opposite)
            name = next((n for n, angles in VIEWS.items() if angles == (azimuth, elevation)), None)
            if name:
                assert frame.figures["orientation"] == NAMED[name]
        assert named >= len(VIEWS_SEEN)  # most views name the marker's side or its opposite at two edges


def test_a_volume_without_patient_axes_is_labelled_by_its_world_axes(tmp_path):
    """A .npy stack (and a phantom) has no patient sides: its edges are +x, -x, ...; a marker at +x, +y, +z lies
    towards the edges so named in the oblique views.  The same stack read with --orientation is a patient's."""
    for axis, name in enumerate(("+x", "+y", "+z")):
        index = [N // 2] * 3
        index[2 - axis] += OFF  # array axes (z, y, x)
        np.save(tmp_path / f"{name[1]}.npy", cube(index))
        wv = clwave.WaveletVolume.from_volume(clwave.load(tmp_path / f"{name[1]}.npy"), levels=1)
        assert not patient_world(wv, Origin())
        assert patient_world(wv, Origin(str(tmp_path / "x.npy"), (("orientation", "--orientation", "LPS"),)))
        xray = source(wv, patient=False)
        named = sum(check_marker(final(xray, *view), name, "−" + name[1]) for view in VIEWS_SEEN[len(VIEWS):])
        assert named >= len(VIEWS_SEEN) - len(VIEWS)
    frame = final(xray, *VIEWS["anterior"], 1.0, None)
    assert frame.figures["orientation"] == dict(left="+x", right="−x", top="+z", bottom="−z")
    assert not patient_world(clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=8), levels=1), Origin())


def test_the_letters_of_oblique_directions():
    """The nearest axis, then the next where the direction is more than 22.5 degrees from the axis towards it."""
    def at(degrees):  # in the x-y plane, from +y towards -x
        return np.array([-np.sin(np.radians(degrees)), np.cos(np.radians(degrees)), 0.0])

    assert [letters(at(d), True) for d in (0, 22, 23, 45, 67, 68, 90)] == ["A", "A", "AL", "AL", "LA", "L", "L"]
    assert letters(at(30), False) == "+y−x" and letters((0, 0, -1), False) == "−z"
    assert letters((0.3, -0.2, 0.9), True) == "S"
    # the camera's roll turns the edges with the picture: a quarter turn clockwise puts the top's label on the right
    rolled = edges(Camera(**named_view("anterior"), size=8, roll=90), True)
    assert rolled == dict(left="I", right="S", top="R", bottom="L")


def test_a_file_no_longer_there_and_a_clw_of_a_patient_file(tmp_path):
    """A .clw made from a NIfTI keeps its patient's axes (its provenance); once the NIfTI is gone they are not known."""
    path = nifti(tmp_path / "a.nii", "L")
    wv = clwave.WaveletVolume.from_volume(clwave.load(path), levels=1)
    wv.save(tmp_path / "a.clw")
    assert patient_world(clwave.WaveletVolume.open(tmp_path / "a.clw"), Origin())
    path.unlink()
    assert not patient_world(clwave.WaveletVolume.open(tmp_path / "a.clw"), Origin())


def test_the_hello_serves_the_named_views_and_the_frames_their_edges(tmp_path):
    """The page's buttons are the hello's ``views``: geometry.VIEWS' angles, each labelled with its side; a frame of a
    view has the edges of its camera."""
    wv = clwave.WaveletVolume.from_volume(clwave.load(nifti(tmp_path / "a.nii", "A")), levels=1)
    with clwave.view(wv, size=SIZE) as v:
        hello = v.server.hello()
        frame = final(v.server.sources["xray"], *VIEWS["left"], 2.0, None)
    assert hello["patient"] is True
    assert {name: (view["azimuth"], view["elevation"]) for name, view in hello["views"].items()} == VIEWS
    assert {name: view["side"] for name, view in hello["views"].items()} == dict(
        anterior="A", posterior="P", left="L", right="R", superior="S", inferior="I")
    assert all(named_view(name) == dict(azimuth=a, elevation=e) for name, (a, e) in VIEWS.items())
    assert frame.figures["orientation"] == NAMED["left"]
