"""A PACS CD of several studies: series listed by study and picked by STUDY/SERIES; the patient shown by ``clwave
info`` and written into no output; the series' Modality carried to the volume, its model and ``.clw`` file, and the
CT presets' warning said from it."""

import json
import zlib

import h5py
import numpy as np
import pytest
from pydicom.uid import generate_uid
from test_dicom_tree import write_sr
from test_loaders import assert_one_line_error, axial, write_dicom_slice

import clwave
from clwave import ClwaveWarning, load
from clwave.cli import main
from clwave.errors import FileFormatError, InputError

PATIENT = dict(PatientName="TRIAL^CHEST", PatientID="P28X")
STUDIES = [dict(StudyInstanceUID=generate_uid(), StudyDate="20261129", StudyDescription="CT Thorax",
                AccessionNumber="ACC11", StudyID="7"),
           dict(StudyInstanceUID=generate_uid(), StudyDate="20261220", StudyDescription="CT Thorax follow-up",
                AccessionNumber="ACC22", StudyID="8")]


def write_stack(folder, rng, number, description, study, count=8, size=(12, 10), modality="CT", **attributes):
    """``count`` axial slices of ``size`` 1.5 mm apart, of one series of ``study`` of the patient; returns the volume
    as load gives it (slope 2, intercept -1024; rows and columns reversed, LPS -> RAS)."""
    folder.mkdir(parents=True)
    uid, stored = generate_uid(), rng.integers(0, 2000, (count, *size))
    for k, (pixels, position) in enumerate(zip(stored, axial(*(1.5 * np.arange(count))))):
        write_dicom_slice(folder / f"IM{k}", pixels, position, uid, number=number, description=description,
                          Modality=modality, **PATIENT, **study, **attributes)
    return (stored * 2.0 - 1024)[:, ::-1, ::-1]


@pytest.fixture
def cd(tmp_path):
    """Two studies of one patient on a CD, each with a series 2: a CT and its follow-up."""
    rng = np.random.default_rng(29)
    top = tmp_path / "cd"
    stacks = {(0, 2): write_stack(top / "ST1" / "SE2", rng, 2, "Soft", STUDIES[0]),
              (0, 3): write_stack(top / "ST1" / "SE3", rng, 3, "Bone", STUDIES[0]),
              (1, 2): write_stack(top / "ST2" / "SE2", rng, 2, "Soft", STUDIES[1])}
    return top, stacks


def test_the_series_of_several_studies_are_listed_by_study_and_picked_by_study_and_series(cd, capsys):
    """The listing heads each study's series with its place in date order and its description, as Horos and RadiAnt
    list them, and never the patient, nor the study's date, accession or ID (PHI: ``info`` shows them); a number both
    studies have is refused naming STUDY/SERIES, which picks by the study's place, date (written with dashes or as
    stored), accession, ID or description."""
    top, stacks = cd
    with pytest.raises(InputError) as excinfo:
        load(top)
    assert_one_line_error(excinfo)
    assert str(excinfo.value) == (
        f"{top} holds 3 DICOM series: study 1 'CT Thorax': series 2 'Soft' (CT, 8 slices of 10 x 12); series "
        f"3 'Bone' (CT, 8 slices of 10 x 12) | study 2 'CT Thorax follow-up': series 2 'Soft' (CT, 8 slices of 10 "
        f"x 12); pick one with series=NUMBER as listed (or its description, or its SeriesInstanceUID; STUDY/NUMBER, "
        f"as a study is listed, where two studies have the number)")
    with pytest.raises(InputError) as excinfo:
        load(top, series=2)
    assert_one_line_error(excinfo)
    assert str(excinfo.value) == (
        f"series=2 matches 2 series in {top}, one in each of 2 studies: study 1 'CT Thorax': series 2 'Soft' (CT, "
        f"8 slices of 10 x 12) | study 2 'CT Thorax follow-up': series 2 'Soft' (CT, 8 slices of 10 x 12); give "
        f"series='1/2' (STUDY/SERIES) or another")
    assert main(["info", str(top), "--series", "Soft"]) == 2
    assert "give --series 1/Soft (STUDY/SERIES) or another" in capsys.readouterr().err
    for series, key in (("1/2", (0, 2)), ("2/2", (1, 2)), ("2/soft", (1, 2)), ("2026-11-29/2", (0, 2)),
                        ("20261220/2", (1, 2)), ("ACC22/soft", (1, 2)), ("7/2", (0, 2)),
                        ("CT Thorax follow-up / 2", (1, 2)), (3, (0, 3)), ("2026-11-29/3", (0, 3))):
        np.testing.assert_array_equal(load(top, series=series).data, stacks[key])
    with pytest.raises(InputError, match="series='1/4' matches none of the 3 DICOM series"):
        load(top, series="1/4")
    with pytest.warns(ClwaveWarning) as caught:  # one study: its series listed as before, without it
        load(top / "ST2")
    assert [str(w.message) for w in caught] == [f"{top / 'ST2'} holds 1 DICOM series: reading its image series, "
                                                 f"series 2 'Soft' (CT, 8 slices of 10 x 12)"]
    (top / "ST2" / "SR").mkdir()
    write_sr(top / "ST2" / "SR" / "IM1", 502, "Dose Report")  # of another study: the image series named with its own
    with pytest.warns(ClwaveWarning, match=r"holds 2 DICOM series: reading its image series, series 2 'Soft' \(CT, 8 "
                                           r"slices of 10 x 12\) of study 2 'CT Thorax follow-up'$"):
        load(top / "ST2")


def test_a_study_named_by_its_place_is_not_taken_for_another_studys_id(tmp_path):
    """``1/2`` is the first study listed even where the second's StudyID is 1 (the place first, then what is stored),
    and a study's ID still picks it where no place is that number."""
    rng = np.random.default_rng(30)
    first, second = (dict(study, StudyID=i) for study, i in zip(STUDIES, ("2", "1")))
    stacks = [write_stack(tmp_path / "cd" / f"ST{i}", rng, 2, "Soft", study) for i, study in enumerate((first, second))]
    for series, stack in (("1/2", stacks[0]), ("2/2", stacks[1]), ("ACC22/2", stacks[1])):
        np.testing.assert_array_equal(load(tmp_path / "cd", series=series).data, stack)
    third = dict(STUDIES[1], StudyInstanceUID=generate_uid(), StudyDate="20270101", StudyID="9")
    stacks.append(write_stack(tmp_path / "cd" / "ST3", rng, 2, "Soft", third))
    np.testing.assert_array_equal(load(tmp_path / "cd", series="9/2").data, stacks[2])


def test_info_shows_the_patient_and_no_output_holds_them(cd, tmp_path, capsys, caplog):
    """The patient's name and ID are PHI: ``clwave info`` shows them on the user's terminal, as every DICOM viewer does;
    the model, its ``.clw`` file, a picture, the warnings and the log hold neither, nor the study's date or
    accession."""
    top, _ = cd
    assert main(["info", str(top), "--series", "2026-12-20/2"]) == 0
    out = capsys.readouterr().out
    assert "patient    TRIAL^CHEST, ID P28X" in out
    assert "study      2026-12-20, 'CT Thorax follow-up', accession ACC22, ID 8" in out
    assert "series     series 2 'Soft', CT, " in out
    model, picture = tmp_path / "m.clw", tmp_path / "p.png"
    assert main(["compress", str(top), "--series", "2026-12-20/2", "--levels", "1", "--keep", "0.5", "-o",
                 str(model)]) == 0
    assert main(["render", str(model), "--size", "16", "-o", str(picture), "--stats", str(tmp_path / "p.json")]) == 0
    said = capsys.readouterr()
    outputs = [p.read_bytes() for p in tmp_path.iterdir() if p.is_file()]
    assert len(outputs) >= 3  # the model, the picture and its figures
    with h5py.File(model) as h5:
        header = json.loads(h5.attrs["header"])
    assert header["modality"] == dict(name="CT", units=None) and header["provenance"]["file"] == str(top)
    for secret in ("TRIAL", "CHEST", "P28X", "ACC22", "2026-12-20", "20261220"):
        for text in (said.out, said.err, caplog.text, json.dumps(header)):
            assert secret not in text
        assert not any(secret.encode() in data for data in outputs)


def test_the_modality_is_carried_to_the_volume_its_model_and_file(cd, tmp_path):
    """load gives a DICOM series' Modality and RescaleType as Volume.modality; the model and its .clw file keep it; a
    file written before it (no key) reads as None; a bad one is refused."""
    top, _ = cd
    vol = load(top, series=3)
    assert vol.modality == dict(name="CT", units=None)
    rng = np.random.default_rng(1)
    mr = write_stack(tmp_path / "mr", rng, 5, "t1", STUDIES[0], modality="MR", RescaleType="US")
    vol = load(tmp_path / "mr")
    np.testing.assert_array_equal(vol.data, mr)
    assert vol.modality == dict(name="MR", units="US")
    model = clwave.WaveletVolume.from_volume(vol, levels=1)
    assert model.modality == vol.modality and model.reconstruct().modality == vol.modality
    assert model.threshold(keep=0.5).modality == vol.modality
    model.save(tmp_path / "m.clw")
    assert clwave.WaveletVolume.open(tmp_path / "m.clw").modality == dict(name="MR", units="US")
    with h5py.File(tmp_path / "m.clw", "r+") as h5:  # as written before the twenty-fourth session: no key
        header = json.loads(h5.attrs["header"])
        del header["modality"]
        text = json.dumps(header)
        h5.attrs.update(header=text, header_crc32=zlib.crc32(text.encode()))
    assert clwave.WaveletVolume.open(tmp_path / "m.clw").modality is None
    assert clwave.Volume(np.zeros((2, 2, 2)), modality="PT").modality == dict(name="PT", units=None)
    assert clwave.Volume(np.zeros((2, 2, 2))).modality is None
    for bad in ("", 3, dict(name="CT")):
        with pytest.raises(InputError, match="is not a DICOM Modality"):
            clwave.Volume(np.zeros((2, 2, 2)), modality=bad)
    with h5py.File(tmp_path / "m.clw", "r+") as h5:
        header["modality"] = dict(name="MR", units=7)
        text = json.dumps(header)
        h5.attrs.update(header=text, header_crc32=zlib.crc32(text.encode()))
    with pytest.raises(FileFormatError, match="modality .* is not a DICOM Modality"):
        clwave.WaveletVolume.open(tmp_path / "m.clw")


def test_a_ct_preset_on_a_series_of_another_modality_warns_from_it(tmp_path, recwarn):
    """A CT preset on an MR series warns from its Modality, though its values reach below air (the values' guess
    would not); on a CT series it is the guess's (no warning where its values hold air), and on a volume of no
    modality the guess warns as before."""
    rng = np.random.default_rng(2)
    study = STUDIES[0]
    write_stack(tmp_path / "mr", rng, 5, "t1", study, modality="MR")
    write_stack(tmp_path / "ct", rng, 2, "Soft", study)
    tf = clwave.TransferFunction.preset("ct-bone")
    with pytest.warns(ClwaveWarning, match=r"the transfer function ct-bone is for CT in Hounsfield units, and this "
                                           r"volume's modality is MR \(its DICOM Modality\), not CT \(for it: "
                                           r"TransferFunction.preset\('mri'\)"):
        tf.classify(load(tmp_path / "mr"))
    recwarn.clear()
    tf.classify(load(tmp_path / "ct"))
    assert not [w for w in recwarn if "is for CT in Hounsfield units" in str(w.message)]
    values = np.random.default_rng(3).uniform(0, 900, (8, 8, 8))
    with pytest.warns(ClwaveWarning, match="this volume's least value is .*, with no air"):
        tf.classify(clwave.Volume(values))


def test_a_lone_lateral_scout_is_named_a_localizer(tmp_path, capsys):
    """One CT image across the table's axis (a lateral scout), or one whose description or ScanOptions names a scout,
    without ImageType LOCALIZER, is named a localizer, not "one 2-D image"; a lone axial image still is one."""
    rng = np.random.default_rng(4)
    cases = [("lateral", dict(orientation=(0, 1, 0, 0, 0, -1)), "a localizer (scout)"),
             ("surview", dict(description="Surview"), "a localizer (scout)"),
             ("options", dict(ScanOptions="SCANOGRAM"), "a localizer (scout)"),
             ("axial", dict(), "one 2-D image")]
    for name, attributes, kind in cases:
        (tmp_path / name).mkdir()
        write_dicom_slice(tmp_path / name / "IM1", rng.integers(0, 9, (6, 5)), (0.0, 0.0, 0.0), generate_uid(),
                          **attributes)
        assert main(["info", str(tmp_path / name)]) == 2
        assert f"(CT, 1 slice of 5 x 6: {kind}); none is an image volume" in capsys.readouterr().err
