"""Multi-frame DICOM files given as the input: frames with positions (enhanced images' per-frame functional groups,
RT Dose's grid frame offsets) read as slices; others refused naming dcm2niix."""

import numpy as np
import pytest
from pydicom.data import get_testdata_file
from test_loaders import assert_one_line_error

import clwave
from clwave.errors import FileFormatError
from clwave.cli import main


def test_an_rt_dose_file_is_its_frames_placed_by_their_offsets():
    """pydicom's rtdose.dcm: 15 frames of 10 x 10, LPS axes (identity orientation), 10 mm pixels, frames 5 mm apart
    from ImagePositionPatient, scaled by DoseGridScaling: in RAS the rows and columns are reversed, the frames kept;
    the centre is the first pixel's position (LPS -> RAS) plus half the grid."""
    import pydicom

    path = get_testdata_file("rtdose.dcm")
    ds = pydicom.dcmread(path)
    vol = clwave.load(path)
    expected = ds.pixel_array.astype(np.float32) * np.float32(ds.DoseGridScaling)
    np.testing.assert_array_equal(vol.data, expected[:, ::-1, ::-1])
    assert vol.spacing == (5.0, 10.0, 10.0)
    x, y, z = (float(v) for v in ds.ImagePositionPatient)
    np.testing.assert_allclose(vol.origin, (-x - 45.0, -y - 45.0, z + 35.0))


def enhanced_ct(path, order, rescale=True, size=(6, 5), series=None, orientation=(1, 0, 0, 0, 1, 0)):
    """An Enhanced CT file of 4 frames of 6 x 5 (rows x columns; ``size``), axial, 2 mm apart, written in ``order`` of
    their positions (frame k holds the value 100 k + pixel index); per-frame rescale slope k + 1 and intercept -1024,
    the orientation and the pixel spacing (0.5, 0.75) in the shared groups; of the series UID ``series`` (default a
    new one)."""
    from pydicom.dataset import Dataset, FileMetaDataset
    from pydicom.sequence import Sequence
    from pydicom.uid import EnhancedCTImageStorage, ExplicitVRLittleEndian, generate_uid

    def item(**attributes):
        ds = Dataset()
        for name, value in attributes.items():
            setattr(ds, name, value)
        return ds

    ds = Dataset()
    ds.file_meta = FileMetaDataset()
    ds.file_meta.TransferSyntaxUID, ds.file_meta.MediaStorageSOPClassUID = ExplicitVRLittleEndian, \
        EnhancedCTImageStorage
    ds.file_meta.MediaStorageSOPInstanceUID = ds.SOPInstanceUID = generate_uid()
    ds.SOPClassUID, ds.SeriesInstanceUID, ds.Modality = EnhancedCTImageStorage, series or generate_uid(), "CT"
    ds.Rows, ds.Columns, ds.NumberOfFrames, ds.SamplesPerPixel = *size, len(order), 1
    ds.BitsAllocated, ds.BitsStored, ds.HighBit, ds.PixelRepresentation = 16, 16, 15, 1
    ds.PhotometricInterpretation = "MONOCHROME2"
    ds.SharedFunctionalGroupsSequence = Sequence([item(
        PlaneOrientationSequence=Sequence([item(ImageOrientationPatient=list(orientation))]),
        PixelMeasuresSequence=Sequence([item(PixelSpacing=[0.5, 0.75], SliceThickness=2.0)]))])
    frames = []
    for k in order:
        groups = item(PlanePositionSequence=Sequence([item(ImagePositionPatient=[10.0, 20.0, 30.0 + 2.0 * k])]))
        if rescale:
            groups.PixelValueTransformationSequence = Sequence([item(RescaleSlope=k + 1, RescaleIntercept=-1024,
                                                                     RescaleType="HU")])
        frames.append(groups)
    ds.PerFrameFunctionalGroupsSequence = Sequence(frames)
    pixels = np.stack([100 * k + np.arange(size[0] * size[1]).reshape(size) for k in order]).astype(np.int16)
    ds.PixelData = pixels.tobytes()
    ds.save_as(path, enforce_file_format=True)
    return pixels


def test_an_enhanced_ct_file_is_its_frames_sorted_rescaled_and_placed(tmp_path, capsys):
    """Frames written out of order come back sorted along the normal (superior last), each rescaled by its own
    slope; rows and columns reversed (LPS -> RAS); spacing (2, 0.5, 0.75), the centre from the first position."""
    path = tmp_path / "ct.dcm"
    enhanced_ct(path, [2, 0, 3, 1])
    vol = clwave.load(path)
    k = np.arange(4)[:, None, None]
    stored = 100 * k + np.arange(30).reshape(6, 5)
    np.testing.assert_array_equal(vol.data, ((k + 1) * stored - 1024.0)[:, ::-1, ::-1])
    assert vol.spacing == (2.0, 0.5, 0.75)
    np.testing.assert_allclose(vol.origin, (-10.0 - 2 * 0.75, -20.0 - 2.5 * 0.5, 30.0 + 3.0))
    assert main(["compress", str(path), "--levels", "1", "--keep", "1", "-o", str(tmp_path / "ct.clw")]) == 0
    capsys.readouterr()
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out  # the frames as load gives them: rescaled, float32, by 4 rescales
    assert "4 x 6 x 5 values of float32, in the file's order of axes (stored as int16)" in out
    assert "1 channel of float32" in out and "rescale    slope 3, intercept -1024 (4 different pairs" in out


def test_an_enhanced_ct_file_s_padding_is_its_least_other_value(tmp_path):
    """Frames mark padding by their stored values as a folder's slices do (PS3.3 C.7.5.1.1.2): stored 0 to 3 (frame
    0's first four pixels) become the least other value after each frame's rescale, frame 0's pixel 4: 4 - 1024."""
    import pydicom

    path = tmp_path / "ct.dcm"
    enhanced_ct(path, [2, 0, 3, 1])
    ds = pydicom.dcmread(path)
    ds.add_new("PixelPaddingValue", "SS", 3)  # its VR (US or SS) is the pixels' (signed here)
    ds.add_new("PixelPaddingRangeLimit", "SS", 0)
    ds.save_as(path)
    with pytest.warns(clwave.ClwaveWarning, match=r"marks 3.33 % of its voxels as padding"):
        vol = clwave.load(path)
    k = np.arange(4)[:, None, None]
    stored = 100 * k + np.arange(30).reshape(6, 5)
    expected = (k + 1) * stored - 1024.0
    expected[stored <= 3] = 4 - 1024.0
    np.testing.assert_array_equal(vol.data, expected[:, ::-1, ::-1])


def test_the_frames_are_read_into_one_float32_volume_as_weighed(tmp_path, monkeypatch):
    """32 frames of 128 x 128 int16 (1 MiB stored, 4 MiB as float32), out of order: read a frame at a time into the
    float32 volume, what reading holds at its peak (traced) is what it weighs first (check_whole), to a frame and
    pydicom's buffers; not the pixels as stored, a sorted copy and the float32 temporaries besides."""
    import tracemalloc

    from clwave.io.loaders import shared
    from clwave.io.loaders.dicom_frames import read_dicom_frames

    path, order = tmp_path / "ct.dcm", np.random.default_rng(3).permutation(32)
    enhanced_ct(path, order, size=(128, 128))
    read_dicom_frames([path])  # the imports it makes, once
    weighed, check_fits = [], shared.check_fits
    monkeypatch.setattr(shared, "check_fits", lambda nbytes, *a: (weighed.append(nbytes), check_fits(nbytes, *a)))
    tracemalloc.start()
    try:
        data = read_dicom_frames([path])[0]
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert weighed == [32 * 128 * 128 * 4] and data.dtype == np.float32 and data.nbytes == weighed[0]
    assert weighed[0] <= peak <= weighed[0] + (1 << 20), (peak, weighed)
    assert data[5, 0, 0] == (5 + 1) * (100 * 5 + 128 * 128 - 1) - 1024.0  # frame 5 by its slope, axes reversed


def test_multi_frame_files_without_positions_are_refused_naming_dcm2niix(tmp_path, capsys):
    """An ultrasound cine and a secondary capture (pydicom's) have frames but no positions: one line naming the file
    as multi-frame and dcm2niix; a single-frame file still points to its folder."""
    for name in ("examples_ybr_color.dcm", "SC_rgb_rle_2frame.dcm"):
        with pytest.raises(FileFormatError, match=r"is a multi-frame DICOM file \(.*frames\) of frames without "
                                                  r"positions .* convert it with dcm2niix"):
            clwave.load(get_testdata_file(name))
    assert main(["compress", get_testdata_file("examples_ybr_color.dcm"), "-o", str(tmp_path / "o.clw")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "dcm2niix" in err and "one DICOM slice" not in err
    single = get_testdata_file("CT_small.dcm")
    with pytest.raises(FileFormatError, match="is one DICOM slice; pass the folder"):
        clwave.load(single)


def _groups_short(ds):
    del ds.PerFrameFunctionalGroupsSequence[-1]


def _spacings_differ(ds):
    from pydicom.dataset import Dataset
    from pydicom.sequence import Sequence

    measures = Dataset()
    measures.PixelSpacing = [0.6, 0.75]
    ds.PerFrameFunctionalGroupsSequence[1].PixelMeasuresSequence = Sequence([measures])


def _offsets_short(ds):
    ds.GridFrameOffsetVector = list(ds.GridFrameOffsetVector)[:-2]


@pytest.mark.parametrize("source, change, needle", [
    ("enhanced", _groups_short, "{path} is a multi-frame DICOM file of 4 frames with 3 per-frame functional groups; "
                                "the file is corrupt"),
    ("enhanced", _spacings_differ, "multi-frame DICOM file {path}: its frames have several pixel spacings or image "
                                   "sizes; convert it with dcm2niix"),
    ("rtdose.dcm", _offsets_short, "{path} is an RT Dose file of 15 frames with 13 grid frame offsets; the file is "
                                   "corrupt")])
def test_frames_at_odds_with_their_geometry_are_named_with_the_file(tmp_path, capsys, source, change, needle):
    """Functional groups or grid offsets that do not match the frames: one line naming the file, not the ValueError
    of a reader's internals."""
    import pydicom

    path = tmp_path / "f.dcm"
    if source == "enhanced":
        enhanced_ct(path, [0, 1, 2, 3])
    else:
        pydicom.dcmread(get_testdata_file(source)).save_as(path)
    ds = pydicom.dcmread(path)
    change(ds)
    ds.save_as(path)
    with pytest.raises(FileFormatError) as err:
        clwave.load(path)
    assert str(err.value).startswith(needle.format(path=path)), str(err.value)
    assert main(["compress", str(path), "-o", str(tmp_path / "o.clw")]) == 2
    assert capsys.readouterr().err == f"clwave: error: {err.value}\n"


def test_frames_sharing_a_position_name_the_converter_not_folders(tmp_path):
    """Two frames of one file at one position (a multi-phase or multi-echo enhanced image): the fix is dcm2niix, which
    separates the acquisitions; a file cannot be split into folders."""
    path = tmp_path / "phases.dcm"
    enhanced_ct(path, [0, 1, 1, 2])
    with pytest.raises(FileFormatError) as err:
        clwave.load(path)
    assert str(err.value) == (f"frame 2 and frame 3 of multi-frame DICOM file {path} share one position; the file "
                              f"may hold several acquisitions (echoes, phases, times), which dcm2niix separates: "
                              f"convert it with dcm2niix (dcm2niix -o OUT_FOLDER {path}) and read the .nii")


def test_dicom_files_without_an_extension_are_known_by_their_preamble(tmp_path, capsys):
    """IM0001 (no extension) and a UID-like name (an extension of digits): the multi-frame file is read as its .dcm
    twin is, a single-frame one points to its folder, and a file of another kind without an extension is still an
    unknown file type."""
    import shutil

    for name in ("IM0001", "1.2.840.10008.99"):
        shutil.copy(get_testdata_file("rtdose.dcm"), tmp_path / name)
        np.testing.assert_array_equal(clwave.load(tmp_path / name).data, clwave.load(get_testdata_file("rtdose.dcm"))
                                      .data)
    shutil.copy(get_testdata_file("CT_small.dcm"), tmp_path / "IM0002")
    with pytest.raises(FileFormatError, match="IM0002 is one DICOM slice; pass the folder"):
        clwave.load(tmp_path / "IM0002")
    (tmp_path / "notes").write_bytes(bytes(300))
    with pytest.raises(FileFormatError, match=r"unknown file type '\(no extension\)'"):
        clwave.load(tmp_path / "notes")
    assert main(["info", str(tmp_path / "IM0001")]) == 0
    assert "values of float32, in the file's order of axes (stored as uint32)" in capsys.readouterr().out


def test_a_file_holding_fewer_frames_than_it_declares_is_refused(tmp_path, capsys):
    """RLE pixel data short of a frame (its last fragment gone): pydicom yields the frames there are, and the slice
    left would hold whatever memory it was given; refused in one line naming the file, the API and the CLI."""
    import pydicom
    from pydicom.encaps import encapsulate, generate_frames
    from pydicom.uid import RLELossless

    path = tmp_path / "short.dcm"
    enhanced_ct(path, [0, 1, 2, 3], size=(16, 16))
    ds = pydicom.dcmread(path)
    ds.compress(RLELossless)
    ds.PixelData = encapsulate(list(generate_frames(ds.PixelData, number_of_frames=4))[:-1])
    ds.save_as(path)
    with pytest.raises(FileFormatError, match="holds 3 frames of pixel data where it declares 4"):
        clwave.load(path)
    assert main(["render", str(path), "-o", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "truncated or corrupt" in err and not (tmp_path / "x.png").exists()


def test_a_series_of_several_enhanced_files_is_one_volume_when_their_frames_form_one_stack(tmp_path):
    """A scanner's file per stack (an enhanced CT split in two files of one series): their frames, sorted along the
    normal across the files, each rescaled by its own slope, are one volume, as one file of them all would be; files
    whose frames share positions (two phases) or orientations differ are refused in one line naming why."""
    import pydicom

    uid = pydicom.uid.generate_uid()
    enhanced_ct(tmp_path / "IM1", [2, 0, 3, 1], series=uid)
    enhanced_ct(tmp_path / "IM2", [5, 7, 4, 6], series=uid)
    vol = clwave.load(tmp_path)
    k = np.arange(8)[:, None, None]
    np.testing.assert_array_equal(vol.data, ((k + 1) * (100 * k + np.arange(30).reshape(6, 5)) - 1024.0)[:, ::-1, ::-1])
    assert vol.spacing == (2.0, 0.5, 0.75) and vol.modality == dict(name="CT", units="HU")
    assert clwave.load(tmp_path, hu_to_mu=True).modality == dict(name="CT", units=None)  # attenuation, not HU
    np.testing.assert_allclose(vol.origin, (-10.0 - 2 * 0.75, -20.0 - 2.5 * 0.5, 30.0 + 7.0))
    enhanced_ct(tmp_path / "IM2", [1, 0, 3, 2], series=uid)  # a second phase at the same positions
    with pytest.raises(FileFormatError) as err:
        clwave.load(tmp_path)
    assert_one_line_error(err)
    assert str(err.value).startswith("frame 2 of IM1 and frame 2 of IM2 of DICOM series ")
    assert str(err.value).endswith(f"share one position; the series may hold several acquisitions (echoes, phases, "
                                   f"times), which dcm2niix separates: convert it with dcm2niix (dcm2niix -o "
                                   f"OUT_FOLDER {tmp_path}) and read the .nii")
    enhanced_ct(tmp_path / "IM2", [5, 7, 4, 6], series=uid, orientation=(1, 0, 0, 0, 0, -1))
    with pytest.raises(FileFormatError) as err:
        clwave.load(tmp_path)
    assert_one_line_error(err)
    assert str(err.value) == (f"DICOM series {uid} in {tmp_path}: its frames lie in several orientations; convert it "
                              f"with dcm2niix (dcm2niix -o OUT_FOLDER {tmp_path}) and read the .nii")
