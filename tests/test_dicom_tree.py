"""From a PACS CD to a series: a tree of folders or a DICOMDIR read as the series it holds (headers only), series
picked by what the listing shows (SeriesNumber, description, UID), non-image series named for what they are, a
localizer among a stack's slices left out, an enhanced multi-frame file listed and loaded as a series."""

import gc
import re
import warnings

import numpy as np
import pydicom
import pytest
from pydicom.dataset import Dataset, FileMetaDataset
from pydicom.sequence import Sequence
from pydicom.uid import ExplicitVRLittleEndian, XRayRadiationDoseSRStorage, generate_uid
from test_dicom_frames import enhanced_ct
from test_loaders import assert_one_line_error, axial, write_dicom_slice, write_series

from clwave import ClwaveWarning, load
from clwave.cli import main
from clwave.errors import FileFormatError, InputError
from clwave.io.loaders import describe, dicom, dicom_tree

STUDY = dict(PatientID="P28", PatientName="TRIAL^CHEST", StudyInstanceUID="1.2.826.0.1.3680043.8.498.28.1",
             StudyDate="20261129", StudyTime="101500", StudyID="1")


def hu(stored):
    """The slices ``write_series`` stores, sorted along z, as load gives them: slope 2, intercept -1024, rows and
    columns reversed (LPS -> RAS)."""
    return (stored * 2.0 - 1024)[:, ::-1, ::-1]


def write_sr(path, number, description):
    """A dose report (X-Ray Radiation Dose SR): a DICOM object of a series, without pixel data."""
    ds = Dataset()
    ds.file_meta = FileMetaDataset()
    ds.file_meta.TransferSyntaxUID, ds.file_meta.MediaStorageSOPClassUID = ExplicitVRLittleEndian, \
        XRayRadiationDoseSRStorage
    ds.file_meta.MediaStorageSOPInstanceUID = ds.SOPInstanceUID = generate_uid()
    ds.SOPClassUID, ds.Modality, ds.SeriesInstanceUID = XRayRadiationDoseSRStorage, "SR", generate_uid()
    ds.SeriesNumber, ds.SeriesDescription, ds.InstanceNumber = number, description, 1
    ds.CompletionFlag, ds.VerificationFlag, ds.ValueType = "COMPLETE", "UNVERIFIED", "CONTAINER"
    ds.ContentDate, ds.ContentTime = "20261129", "101500"
    code = Dataset()
    code.CodeValue, code.CodingSchemeDesignator, code.CodeMeaning = "113701", "DCM", "X-Ray Radiation Dose Report"
    ds.ConceptNameCodeSequence = Sequence([code])
    for name, value in STUDY.items():
        setattr(ds, name, value)
    ds.save_as(path, enforce_file_format=True)


def write_cd(top, rng):
    """A PACS export: DICOM/PAT1/ST1/SE<k>/IM<n>: a scout of 2 localizers (AP, lateral), a stack of 4 axial slices,
    a dose report.  Returns the stack's stored pixels (sorted along z)."""
    study = top / "DICOM" / "PAT1" / "ST1"
    for k in (1, 2, 3):
        (study / f"SE{k}").mkdir(parents=True)
    scout = generate_uid()
    for n, orientation in enumerate([(1, 0, 0, 0, 0, -1), (0, 1, 0, 0, 0, -1)], 1):  # coronal, sagittal
        write_dicom_slice(study / "SE1" / f"IM{n}", rng.integers(0, 9, (6, 5)), (0.0, 0.0, 0.0), scout, number=1,
                          description="Topogram", orientation=orientation, InstanceNumber=n,
                          ImageType=["ORIGINAL", "PRIMARY", "LOCALIZER"], **STUDY)
    stored = write_series(study / "SE2", rng, axial(0.0, 2.0, 4.0, 6.0), generate_uid(), ["IM1", "IM2", "IM3", "IM4"],
                          number=2, description="Thorax 1.0 Br40", InstanceNumber=1, **STUDY)
    write_sr(study / "SE3" / "IM1", 502, "Dose Report")
    return stored


def write_dicomdir(source, export):
    """The CD below ``source`` written again as pydicom's FileSet writes one: a DICOMDIR at ``export`` and the files
    in its own tree (PT000000/ST000000/...)."""
    from pydicom.fileset import FileSet

    with warnings.catch_warnings():  # pydicom's staging folder, left to its finalizer
        warnings.simplefilter("ignore", ResourceWarning)
        fileset = FileSet()
        for path in sorted(source.rglob("IM*")):
            fileset.add(path)
        fileset.write(export)
        del fileset
        gc.collect()


@pytest.fixture
def rng():
    return np.random.default_rng(28)


def test_a_cd_its_study_folder_and_its_dicomdir_are_read_as_their_one_image_series(tmp_path, rng):
    """The CD's top and its study folder hold no slices of their own: the series below them are found, and the one
    image series among them (the others a scout and a dose report) is loaded, named in a warning.  A DICOMDIR
    (written by pydicom's FileSet, which lays the files out its own way) is read as the series it lists."""
    stored = write_cd(tmp_path / "cd", rng)
    for given in (tmp_path / "cd", tmp_path / "cd" / "DICOM" / "PAT1" / "ST1"):
        with pytest.warns(ClwaveWarning, match=rf"{given} holds 3 DICOM series: reading its image series, series 2 "
                                               r"'Thorax 1.0 Br40' \(CT, 4 slices of 5 x 6\)"):
            vol = load(given)
        np.testing.assert_array_equal(vol.data, hu(stored))
        assert vol.spacing == pytest.approx((2.0, 0.7, 0.9))
    write_dicomdir(tmp_path / "cd", tmp_path / "export")
    with pytest.warns(ClwaveWarning, match="holds 3 DICOM series: reading its image series, series 2"):
        vol = load(tmp_path / "export" / "DICOMDIR")
    np.testing.assert_array_equal(vol.data, hu(stored))
    files = [p for p in sorted((tmp_path / "export").rglob("*")) if p.is_file() and p.name != "DICOMDIR"]
    assert len(files) == 7 and files[0].parent != tmp_path / "export"  # FileSet's own tree: PT000000/ST000000/...
    files[3].unlink()  # a CD copied short: the DICOMDIR names what is missing
    with pytest.raises(FileFormatError) as excinfo:
        load(tmp_path / "export" / "DICOMDIR")
    assert_one_line_error(excinfo)
    assert str(excinfo.value) == f"{tmp_path / 'export' / 'DICOMDIR'} refers to 1 missing file (e.g. {files[3]}); " \
                                 "give the folder the series are in"


def test_non_image_series_are_named_for_what_they_are(tmp_path, rng, capsys):
    """A dose report (given as its file, its folder, or picked), a scout and a single 2-D image are named for what
    they are, not as slices of a volume to put in a folder."""
    write_cd(tmp_path / "cd", rng)
    study = tmp_path / "cd" / "DICOM" / "PAT1" / "ST1"
    cases = [
        (study / "SE3" / "IM1", dict(), f"{study / 'SE3' / 'IM1'} is a structured report (series 502 'Dose Report'), "
                                        "not an image volume"),
        (study / "SE3", dict(), f"{study / 'SE3'} holds 1 DICOM series: series 502 'Dose Report' (SR: a structured "
                                "report); none is an image volume"),
        (study / "SE1", dict(), "series 1 'Topogram' (CT, 2 slices of 5 x 6: a localizer (scout)); none is an image "
                                "volume"),
        (tmp_path / "cd", dict(series="dose report"), f"series 502 'Dose Report' in {tmp_path / 'cd'} is a structured "
                                                      "report, not an image volume; its image series: series 2 'Thorax "
                                                      "1.0 Br40' (CT, 4 slices of 5 x 6)"),
    ]
    for given, options, message in cases:
        with pytest.raises(FileFormatError) as excinfo:
            load(given, **options)
        assert_one_line_error(excinfo)
        assert message in str(excinfo.value)
    (study / "SE1" / "IM2").unlink()  # one scout image left, not marked as a localizer: one 2-D image
    write_dicom_slice(study / "SE1" / "IM1", rng.integers(0, 9, (6, 5)), (0.0, 0.0, 0.0), generate_uid(), number=1)
    assert main(["info", str(study / "SE1")]) == 2
    assert "series 1 (CT, 1 slice of 5 x 6: one 2-D image); none is an image volume" in capsys.readouterr().err


def test_series_is_picked_by_number_description_or_uid_and_an_ambiguous_one_is_refused(tmp_path, rng, capsys):
    """--series takes what the listing shows; a number two series share (two studies on one CD) is refused, naming
    both with their UIDs, and either is picked by its UID."""
    uids = [generate_uid() for _ in range(3)]
    for name in "abc":
        (tmp_path / name).mkdir()
    bone = write_series(tmp_path / "a", rng, axial(0.0, 1.0, 2.0), uids[0], ["1", "2", "3"], number=3,
                        description="Bone")
    soft = write_series(tmp_path / "b", rng, axial(0.0, 2.0), uids[1], ["1", "2"], number=2, description="Soft")
    again = write_series(tmp_path / "c", rng, axial(0.0, 2.0), uids[2], ["1", "2"], number=2, description="Later")
    with pytest.raises(InputError) as excinfo:
        load(tmp_path)
    assert_one_line_error(excinfo)
    assert str(excinfo.value) == (
        f"{tmp_path} holds 3 DICOM series: series 2 'Later' (CT, 2 slices of 5 x 6); series 2 'Soft' (CT, 2 slices of "
        f"5 x 6); series 3 'Bone' (CT, 3 slices of 5 x 6); pick one with series=NUMBER as listed (or its description, "
        f"or its SeriesInstanceUID)")
    for series, stored in ((3, bone), ("3", bone), ("bone", bone), ("SOFT", soft), (uids[2], again), (uids[1], soft)):
        np.testing.assert_array_equal(load(tmp_path, series=series).data, hu(stored))
    with pytest.raises(InputError) as excinfo:
        load(tmp_path, series=2)
    assert_one_line_error(excinfo)
    assert f"series=2 matches 2 series in {tmp_path}: series 2 'Later' (CT, 2 slices of 5 x 6, {uids[2]}); series 2 " \
           f"'Soft' (CT, 2 slices of 5 x 6, {uids[1]}); give its SeriesInstanceUID" == str(excinfo.value)
    assert main(["info", str(tmp_path), "--series", "2"]) == 2
    assert "--series 2 matches 2 series" in capsys.readouterr().err
    assert main(["info", str(tmp_path), "--series", "Bone"]) == 0
    assert f"series     series 3 'Bone', CT, {uids[0]}" in capsys.readouterr().out


def test_a_localizer_among_the_slices_is_left_out_and_another_odd_slice_named(tmp_path, rng):
    """A scout the scanner put into the axial series (ImageType LOCALIZER, coronal) is left out with a warning naming
    its file, as dcm2niix and Slicer split it off; an odd slice not marked as one is refused, named."""
    uid = generate_uid()
    stored = write_series(tmp_path, rng, axial(0.0, 1.0, 2.0), uid, ["IM1", "IM2", "IM3"], number=2)
    write_dicom_slice(tmp_path / "IM0", rng.integers(0, 9, (6, 5)), (0.0, 0.0, 0.0), uid, number=2,
                      orientation=(1, 0, 0, 0, 0, -1), ImageType=["ORIGINAL", "PRIMARY", "LOCALIZER"])
    with pytest.warns(ClwaveWarning, match=r"DICOM series 2 holds 1 localizer image among its 3 slices \(IM0\): left "
                                           r"out"):
        vol = load(tmp_path)
    np.testing.assert_array_equal(vol.data, hu(stored))
    write_dicom_slice(tmp_path / "IM0", rng.integers(0, 9, (6, 5)), (0.0, 0.0, 0.0), uid, number=2,
                      orientation=(1, 0, 0, 0, 0, -1))
    with pytest.raises(FileFormatError) as excinfo:
        load(tmp_path)
    assert_one_line_error(excinfo)
    assert "mixes slice orientations: IM0 has ImageOrientationPatient 1, 0, 0, 0, 0, -1 where 3 of its 4 slices have " \
           "1, 0, 0, 0, 1, 0 (a localizer?)" in str(excinfo.value)


def test_an_enhanced_multi_frame_file_is_listed_and_loaded_as_a_series(tmp_path, rng, capsys):
    """A folder of one Enhanced CT file is its series, as the file is; in a tree beside a stack it is listed by its
    frames and picked by its number."""
    (tmp_path / "SE10").mkdir()
    enhanced_ct(tmp_path / "SE10" / "IM1", [2, 0, 3, 1])
    file = load(tmp_path / "SE10" / "IM1")
    np.testing.assert_array_equal(load(tmp_path / "SE10").data, file.data)
    (tmp_path / "SE2").mkdir()
    write_series(tmp_path / "SE2", rng, axial(0.0, 1.0), generate_uid(), ["IM1", "IM2"], number=2, description="Soft")
    with pytest.raises(InputError, match=r"series 2 'Soft' \(CT, 2 slices of 5 x 6\); series \S+ \(CT, 4 frames of 5 x "
                                         r"6\); pick one"):
        load(tmp_path)
    uid = str(pydicom.dcmread(tmp_path / "SE10" / "IM1").SeriesInstanceUID)
    np.testing.assert_array_equal(load(tmp_path, series=uid).data, file.data)
    facts = describe(tmp_path, series=uid)  # info: the series, and the frames as read (float32, rescaled)
    assert facts["series"] == dict(number=None, description="", modality="CT", uid=uid, units="HU",
                                   study=dict.fromkeys(("date", "time", "description", "accession", "id", "uid"), ""),
                                   patient=dict(name="", id=""))
    assert facts["dtype"] == "float32" and facts["stored_dtype"] == "int16" and len(facts["rescale"]) == 4


def test_the_walk_reads_headers_only_and_is_bounded(tmp_path, rng, monkeypatch):
    """The tree is read from its headers (no pixel of the series not loaded, none to list them), and a folder of more
    files below it than a CD holds is refused in one line, not walked for minutes."""
    write_cd(tmp_path / "cd", rng)
    (tmp_path / "cd" / "DICOM" / "PAT1" / "ST2").mkdir()
    write_series(tmp_path / "cd" / "DICOM" / "PAT1" / "ST2", rng, axial(0.0, 1.0), generate_uid(), ["IM1", "IM2"])
    monkeypatch.setattr(dicom, "_dicom_pixels", lambda path: pytest.fail(f"{path}'s pixels were read"))
    with pytest.raises(InputError, match="holds 4 DICOM series"):
        load(tmp_path / "cd")
    monkeypatch.setattr(dicom_tree, "MAX_FILES", 5)
    with pytest.raises(FileFormatError) as excinfo:
        load(tmp_path / "cd")
    assert_one_line_error(excinfo)
    assert str(excinfo.value) == f"folder {tmp_path / 'cd'} holds more than 5 files in the folders below it; give " \
                                 "the folder of one study or series"


def test_a_compressed_syntax_without_its_decoder_names_the_pip_command(tmp_path, rng, monkeypatch):
    """JPEG Lossless (the commonest syntax on PACS CDs) where no decoder is installed (clwave depends on python-gdcm,
    which decodes it: an install without it): the refusal gives the command that installs it, as README's install
    would need it."""
    from pydicom.encaps import encapsulate
    from pydicom.pixels import get_decoder
    from pydicom.uid import JPEGLosslessSV1

    decoder = type(get_decoder(JPEGLosslessSV1))
    monkeypatch.setattr(decoder, "is_available", property(lambda self: False))
    monkeypatch.setattr(decoder, "missing_dependencies", property(lambda self: [  # pydicom's words, none installed
        "gdcm - requires gdcm>=3.0.10", "pylibjpeg - requires pylibjpeg>=2.0 and pylibjpeg-libjpeg>=2.1"]))
    uid = generate_uid()
    for k, position in enumerate(axial(0.0, 1.0)):
        write_dicom_slice(tmp_path / f"IM{k}", rng.integers(0, 9, (6, 5)), position, uid)
        ds = pydicom.dcmread(tmp_path / f"IM{k}")
        ds.file_meta.TransferSyntaxUID = JPEGLosslessSV1  # the syntax only: no decoder reads past the refusal
        ds.PixelData = encapsulate([ds.PixelData])
        ds["PixelData"].VR, ds["PixelData"].is_undefined_length = "OB", True
        ds.save_as(tmp_path / f"IM{k}")
    with pytest.raises(FileFormatError) as excinfo:
        load(tmp_path)
    assert_one_line_error(excinfo)
    assert "install one: pip install python-gdcm in clwave's environment (a clone set up by tools/setup.sh: " \
           ".venv/bin/pip install python-gdcm), or convert the series with dcm2niix" in str(excinfo.value)


def write_jpeg_lossless_series(folder, rng, syntax="JPEGLosslessProcess14_1"):
    """Three slices compressed in JPEG Lossless by GDCM (pydicom has no encoder for it); returns their stored values."""
    import gdcm

    uid, stored = generate_uid(), rng.integers(0, 4000, (3, 6, 5))
    for k, (pixels, position) in enumerate(zip(stored, axial(0.0, 1.0, 2.0))):
        write_dicom_slice(folder / f"IM{k}", pixels, position, uid)
        reader, change, writer = gdcm.ImageReader(), gdcm.ImageChangeTransferSyntax(), gdcm.ImageWriter()
        reader.SetFileName(str(folder / f"IM{k}"))
        assert reader.Read()
        change.SetTransferSyntax(gdcm.TransferSyntax(getattr(gdcm.TransferSyntax, syntax)))
        change.SetInput(reader.GetImage())
        assert change.Change()
        writer.SetFileName(str(folder / f"IM{k}"))
        writer.SetFile(reader.GetFile())
        writer.SetImage(change.GetOutput())
        assert writer.Write()
    return stored


@pytest.mark.parametrize("syntax", ["JPEGLosslessProcess14_1", "JPEGLosslessProcess14"])
def test_jpeg_lossless_series_are_decoded(tmp_path, rng, syntax):
    """A series in JPEG Lossless (1.2.840.10008.1.2.4.70 and .57) reads as the stored pixels it was made from,
    through python-gdcm, a dependency of clwave."""
    from pydicom.uid import JPEGLossless, JPEGLosslessSV1

    stored = write_jpeg_lossless_series(tmp_path, rng, syntax)
    for k in range(3):
        assert pydicom.dcmread(tmp_path / f"IM{k}").file_meta.TransferSyntaxUID == \
            (JPEGLosslessSV1 if syntax.endswith("_1") else JPEGLossless)
    np.testing.assert_array_equal(load(tmp_path).data, hu(stored))


def test_a_corrupt_jpeg_lossless_slice_is_refused_with_the_decoders_reason(tmp_path, rng):
    """A slice whose Huffman table is overwritten: one line naming the file and what the decoder said (pydicom puts
    its plugins' reasons on the lines after "raised by all available plugins:"; only the first was kept)."""
    write_jpeg_lossless_series(tmp_path, rng)
    ds = pydicom.dcmread(tmp_path / "IM1")
    stream = bytearray(ds.PixelData)
    table = stream.find(b"\xff\xc4")  # DHT
    stream[table + 5:table + 25] = b"\xff" * 20
    ds.PixelData = bytes(stream)
    ds.save_as(tmp_path / "IM1")
    with pytest.raises(FileFormatError) as excinfo:
        load(tmp_path)
    assert_one_line_error(excinfo)
    assert re.fullmatch(rf"cannot read {re.escape(str(tmp_path / 'IM1'))}: RuntimeError: Unable to decode .* plugins: "
                        r"gdcm: \S.*; the file may be truncated or corrupt", str(excinfo.value))


def test_odd_series_values_are_refused_as_values_not_as_the_files(tmp_path, rng):
    """A value that is no number (non-ASCII digits, a sign twice, a bool) names no series: refused as the option's
    value, listing the series, never blamed on the folder's files (``int("²")`` raised ValueError)."""
    for name in "ab":
        (tmp_path / name).mkdir()
    write_series(tmp_path / "a", rng, axial(0.0, 1.0), generate_uid(), ["1", "2"], number=2, description="Bone")
    write_series(tmp_path / "b", rng, axial(0.0, 1.0), generate_uid(), ["1", "2"], number=3, description="Soft")
    for series in ("--5", "²", "٣", True):
        with pytest.raises(InputError) as excinfo:
            load(tmp_path, series=series)
        assert_one_line_error(excinfo)
        assert str(excinfo.value).startswith(f"series={series!r} matches none of the 2 DICOM series in {tmp_path}: ")


def test_a_dicomdir_naming_files_outside_its_folder_is_refused(tmp_path, rng):
    """PS3.10's file IDs are components below the DICOMDIR's folder: a record that climbs out of it ("..") is
    refused before any file it names is opened."""
    write_cd(tmp_path / "cd", rng)
    write_dicomdir(tmp_path / "cd", tmp_path / "export")
    dicomdir = tmp_path / "export" / "DICOMDIR"
    ds = pydicom.dcmread(dicomdir)
    record = next(r for r in ds.DirectoryRecordSequence if r.get("ReferencedFileID"))
    with warnings.catch_warnings():  # pydicom: ".." is no valid CS value, which is the point
        warnings.simplefilter("ignore", UserWarning)
        record.ReferencedFileID = ["..", "cd", "DICOM", "PAT1", "ST1", "SE2", "IM1"]
        ds.save_as(dicomdir)
    with pytest.raises(FileFormatError) as excinfo:
        load(dicomdir)
    assert_one_line_error(excinfo)
    assert str(excinfo.value) == f"{dicomdir} refers to a file outside its folder ('../cd/DICOM/PAT1/ST1/SE2/IM1'); " \
                                 "it may be corrupt or crafted: give the folder the series are in"
