"""DICOM discovery: a folder of slices, a tree of folders (a CD's top, a study folder) or a ``DICOMDIR``, read as the
series it holds from their headers alone, listed as PACS viewers list them (number, description, modality, slices or
frames, image size), one picked by ``series=`` (its SeriesNumber, description or UID), and non-image series (a
localizer, a secondary capture, a structured report...) named for what they are (docs/coordinates.md §1)."""

from __future__ import annotations

import os
import re
from collections import defaultdict
from pathlib import Path

import numpy as np

from ...errors import FileFormatError, InputError
from . import dicom, dicom_frames
from .shared import SUPPORTED, folder_files, note, reading

#: the most files a tree walk reads headers of (about 0.9 ms each, docs/benchmarks.md §24): past it, the folder is not
#: one CD or study
MAX_FILES = 20_000
# what a series without pixel data is, by its Modality
_NON_IMAGE = {"SR": "a structured report", "PR": "a presentation state", "KO": "a key object selection",
              "RTSTRUCT": "an RT structure set", "RTPLAN": "an RT plan", "DOC": "an encapsulated document"}
# the words scanners mark a scout with (Siemens' topogram, Canon's scanogram, Philips' surview and survey, GE's scout)
_SCOUT_WORDS = re.compile(r"\b(LOCALI[SZ]ER|SCOUT|TOPOGRAM|SCANOGRAM|SURVIEW|SURVEY)\b", re.IGNORECASE)
_CLI_PICK = "--series NUMBER as listed (or its description, or its SeriesInstanceUID)"
_API_PICK = "series=NUMBER as listed (or its description, or its SeriesInstanceUID)"


class Series:
    """One series' files ``[(path, header)]`` (headers read without pixel data), and what it is: ``kind`` None for a
    volume (slices, or one multi-frame file), else the words for what it is instead; ``study`` its study's facts
    (:func:`.dicom.study_facts`), ``key`` what names that study in ``series=STUDY/SERIES`` (:func:`_study_keys`)."""

    def __init__(self, uid, files):
        self.uid, self.files = uid, files
        self.facts = dicom.series_facts(next((h for _, h in files if not _scout(h)), files[0][1]))
        self.number, self.description, self.modality = (self.facts[k] for k in ("number", "description", "modality"))
        self.study, self.key = self.facts["study"], None
        self.name = dicom.series_name(self.facts)
        self.frames = sum(int(h.get("NumberOfFrames") or 1) for _, h in files)
        self.size = next(((int(h.Rows), int(h.Columns)) for _, h in files if "Rows" in h and "Columns" in h), None)
        self.kind = _kind_of(files, self.modality)

    def shown(self, uid=False) -> str:
        """How a listing shows it: name, then modality, slices or frames and image size, or what it is."""
        facts = [self.modality]
        if self.size is not None:  # width x height, as viewers give an image's size
            unit = "frames" if self.frames > len(self.files) else "slices" if self.frames > 1 else "slice"
            facts.append(f"{self.frames} {unit} of {self.size[1]} x {self.size[0]}")
        what = "" if self.kind is None else f": {self.kind}"
        return f"{self.name} ({', '.join(f for f in facts if f)}{what}{', ' + self.uid if uid else ''})"

    def study_shown(self) -> str:
        """Its study as a listing heads its series: "study 1 'CT Thorax'", by its key and description; never its date,
        accession number or ID, nor the patient (PHI: ``clwave info`` shows them)."""
        described = f" '{self.study['description']}'" if self.study["description"] else ""
        return f"study {self.key}{described}"


def _kind_of(files, modality):
    """None for a series that is a volume, else what it is, in words."""
    headers = [h for _, h in files]
    sop = getattr(headers[0].get("SOPClassUID"), "name", "") or ""
    if not any("PixelData" in h for h in headers):
        return _NON_IMAGE.get(modality) or ("a structured report" if sop.endswith("SR Storage") else
                                            f"a {sop.removesuffix(' Storage') or 'DICOM object'} without pixel data")
    if "Secondary Capture" in sop:
        return "a secondary capture (a picture of a screen or document)"
    if all(_scout(h) for h in headers):
        return "a localizer (scout)"
    if any(int(h.get("NumberOfFrames") or 1) > 1 for h in headers):  # its files' frames are placed together
        return None if all(int(h.get("NumberOfFrames") or 1) > 1 for h in headers) else \
            f"{len(files)} files, some single images and some of several frames (give one multi-frame file of them, " \
            f"e.g. {next(f for f, h in files if int(h.get('NumberOfFrames') or 1) > 1)})"
    if len(files) == 1:
        return "a localizer (scout)" if _projection(headers[0], modality) else "one 2-D image"
    # 2 or 3 views, each its own orientation (an AP and a lateral): a scout without ImageType LOCALIZER
    cosines = [np.array(h.get("ImageOrientationPatient") or [np.nan], float) for h in headers]
    views = {tuple(np.round(c, 3)) for c in cosines if c.shape == (6,) and np.all(np.abs(c) <= 1.001)}
    return "a localizer (scout)" if len(files) <= 3 and len(views) == len(files) else None


def _projection(header, modality) -> bool:
    """Whether a lone image is a projection (a scout) though its ImageType says no LOCALIZER: its ImageType,
    ScanOptions or description names one as scanners do (SCOUT, TOPOGRAM, SCANOGRAM, SURVIEW, SURVEY), or it is a
    CT image across the table's axis (a lateral or AP view: a CT scanner's slices are axial, tilted 30 degrees at
    most)."""
    said = [*(header.get("ImageType") or []), header.get("ScanOptions") or "", header.get("SeriesDescription") or ""]
    if _SCOUT_WORDS.search(" ".join(map(str, said))):
        return True
    cosines = np.array(header.get("ImageOrientationPatient") or [np.nan] * 6, float)
    normal = np.cross(cosines[:3], cosines[3:]) if cosines.shape == (6,) else np.full(3, np.nan)
    return modality == "CT" and bool(abs(normal[2]) < np.cos(np.radians(60)))


def describe_file(path, header) -> str | None:
    """What a single-frame DICOM file given as the input is, where it is no slice of a volume (None where it is)."""
    kind = _kind_of([(path, header)], str(header.get("Modality") or ""))
    if kind is None or kind == "one 2-D image":
        return None
    return f"{path} is {kind} ({dicom.series_name(dicom.series_facts(header))}), not an image volume"


def read_dicom(path, series, progress_bar, fits=None):
    """The volume of the series ``series=`` picks (or the only image series) in the folder, tree or DICOMDIR
    ``path``: slices (:func:`.dicom.read_dicom_folder`) or one multi-frame file (:func:`.dicom_frames.
    read_dicom_frames`); a localizer mixed into a stack of slices is left out with a warning naming it."""
    tree, found = find_series(path)
    chosen = pick(path, found, series, tree)
    if chosen.kind is not None:
        others = [s.shown() for s in found if s.kind is None]
        listed = f"; its image series: {'; '.join(others)}" if others else "; it holds no image series"
        raise FileFormatError(f"{chosen.name} in {path} is {chosen.kind}, not an image volume{listed}")
    where = f"DICOM {chosen.name} in {path}"
    if chosen.frames > len(chosen.files):
        files = [file for file, _ in chosen.files]
        return dicom_frames.read_dicom_frames(files, fits, where if len(files) > 1 else None)
    return (*dicom.read_dicom_folder(where, path, _without_localizers(chosen), progress_bar, fits),
            dicom.modality_of(chosen.facts))


def _without_localizers(series):
    """The series' files without the localizers (ImageType LOCALIZER) a scanner put among its slices, warned of."""
    scouts = [path.name for path, h in series.files if _scout(h)]
    if not scouts:
        return series.files
    note(f"DICOM {series.name} holds {len(scouts)} localizer image{'s' * (len(scouts) > 1)} among its "
         f"{len(series.files) - len(scouts)} slices ({', '.join(scouts[:3])}{', ...' * (len(scouts) > 3)}): left out")
    return [(path, h) for path, h in series.files if not _scout(h)]


def _scout(header) -> bool:
    return "LOCALIZER" in (header.get("ImageType") or [])


def find_series(path):
    """``(tree, [Series])``: the series of the DICOM files in the folder ``path``, else (it holds none of its own)
    in the folders below it, or those a DICOMDIR file ``path`` lists (``tree``: True for the last two), by
    SeriesNumber; refused where it holds none."""
    if path.is_file():
        tree, found = True, _headers(_dicomdir_files(path))
    else:
        tree, found = False, _headers(folder_files(path))
        if not found:
            tree, found = True, _headers(_walk(path))
    if not found:
        below = " (nor the folders below it)" if path.is_dir() else ""
        raise FileFormatError(f"folder {path} holds no TIFF, PNG or JPEG slices and no DICOM files{below}; "
                              f"supported inputs: {SUPPORTED}")
    groups = defaultdict(list)
    for file, header in found:
        groups[str(header.SeriesInstanceUID)].append((file, header))
    listed = [Series(uid, files) for uid, files in groups.items()]
    _study_keys(listed)
    return tree, sorted(listed, key=lambda s: (s.study["date"], s.study["time"], s.study["uid"], s.number is None,
                                               s.number or 0, s.description, s.uid))


def _study_keys(listed):
    """Give each series its study's ``key``: the study's place, from 1, in the order of their dates (a CD of a CT and
    its follow-up: 1 and 2), what names it in listings and in ``STUDY/SERIES`` without a patient's dates or numbers."""
    studies = sorted({(s.study["date"], s.study["time"], s.study["uid"]) for s in listed})
    place = {uid: str(i) for i, (_, _, uid) in enumerate(studies, 1)}
    for s in listed:
        s.key = place[s.study["uid"]]


def _headers(paths):
    """``[(path, header)]`` of the DICOM files among ``paths`` that belong to a series (a DICOMDIR does not), read
    without their pixel data; a DICOM file of no series is cut before it (refused)."""
    from pydicom.misc import is_dicom
    from pydicom.uid import MediaStorageDirectoryStorage

    found = []
    for path in paths:
        with reading(path):
            if not is_dicom(path):
                continue
            header = dicom.dcmread(path, defer_size=1024)  # PixelData noted (its length), not read
        if "SeriesInstanceUID" in header:
            found.append((path, header))
        elif header.file_meta.get("MediaStorageSOPClassUID") != MediaStorageDirectoryStorage:
            raise FileFormatError(f"DICOM file {path} has no SeriesInstanceUID; it may be truncated or corrupt: move "
                                  "it out of the folder")
    return found


def _walk(top):
    """The files below the folder ``top`` (hidden ones left out), refused past :data:`MAX_FILES`."""
    files = []
    for folder, subfolders, names in os.walk(top):
        subfolders[:] = sorted(d for d in subfolders if not d.startswith("."))
        files += [Path(folder, n) for n in sorted(names) if not n.startswith(".")]
        if len(files) > MAX_FILES:
            raise FileFormatError(f"folder {top} holds more than {MAX_FILES:,} files in the folders below it; give "
                                  f"the folder of one study or series")
    return files


def _dicomdir_files(path):
    """The files a DICOMDIR's records refer to (ReferencedFileID, relative to its folder), each checked to exist.  Read
    from its records: pydicom's FileSet stages a temporary folder, left to its finalizer."""
    with reading(path):
        records = dicom.dcmread(path).get("DirectoryRecordSequence") or []
    ids = [[i] if isinstance(i, str) else list(i) for i in (r.ReferencedFileID for r in records
                                                              if r.get("ReferencedFileID"))]
    if len(ids) > MAX_FILES:
        raise FileFormatError(f"{path} refers to {len(ids):,} files, more than {MAX_FILES:,}; give the folder of one "
                              "study or series")
    # PS3.10 §8.2: a file ID is up to 8 components of its folder's tree, never a way out of it
    outside = next((i for i in ids if any(not c or c in (".", "..") or any(ch in c for ch in "/\\:") for c in i)), None)
    if outside is not None:
        raise FileFormatError(f"{path} refers to a file outside its folder ({'/'.join(outside)!r}); it may be corrupt "
                              "or crafted: give the folder the series are in")
    files = [path.parent.joinpath(*i) for i in ids]
    missing = [f for f in files if not f.is_file()]
    if missing:
        raise FileFormatError(f"{path} refers to {len(missing)} missing file{'s' * (len(missing) > 1)} (e.g. "
                              f"{missing[0]}); give the folder the series are in")
    return files


def pick(path, found, series, tree):
    """The series ``series=`` names (SeriesNumber, description without regard to case, or SeriesInstanceUID; where
    the input holds several studies, ``STUDY/SERIES`` with STUDY its place as listed, date, accession number,
    StudyID, description or UID), or without it the only image series (named in a warning when the input held others,
    or was a tree); a value that names several is refused, naming them and how to tell them apart."""
    images = [s for s in found if s.kind is None]
    if series is None:
        if len(images) == 1:
            if tree or len(found) > 1:
                note(f"{path} holds {_count(found)}: reading its image series, {_named(found, images[0])}")
            return images[0]
        held = f"{path} holds {_count(found)}: {_listing(found)}; "
        if not images:
            raise FileFormatError(held + "none is an image volume")
        studies = "; STUDY/NUMBER, as a study is listed, where two studies have the number)" \
            if len({s.study["uid"] for s in found}) > 1 else ")"
        raise InputError(held + "pick one with " + _API_PICK[:-1] + studies,
                         cli=held + "pick one with " + _CLI_PICK[:-1] + studies)
    text = str(series).strip()
    matches = _matching(found, text)
    if len(matches) == 1:
        return matches[0]
    api, cli = f"series={series!r}", f"--series {text}"
    if len({s.study["uid"] for s in matches}) == len(matches) > 1:  # one a study: told apart by STUDY/SERIES
        told = [f"{s.key}/{text.rpartition('/')[2]}" for s in matches]
        how = f"matches {len(matches)} series in {path}, one in each of {len(matches)} studies: {_listing(matches)}"
        raise InputError(f"{api} {how}; give series={told[0]!r} (STUDY/SERIES) or another",
                         cli=f"{cli} {how}; give --series {told[0]} (STUDY/SERIES) or another")
    if matches:
        how = f"matches {len(matches)} series in {path}: {'; '.join(s.shown(uid=True) for s in matches)}; give " \
              f"its SeriesInstanceUID"
    else:
        how = f"matches none of the {_count(found)} in {path}: {_listing(found)}"
    raise InputError(f"{api} {how}", cli=f"{cli} {how}")


def _matching(found, text):
    """The series ``text`` names: as a whole (number, description, UID), else split at a "/" into a study (its place
    as listed first, else its date as stored or written with dashes, accession number, StudyID, description or UID)
    and a series in it."""
    def names(s, said):
        number = int(said) if re.fullmatch(r"-?[0-9]+", said) else None  # ASCII digits: "²".isdigit() is True
        return number is not None and s.number == number or s.description.casefold() == said.casefold() or \
            s.uid == said

    def stored(s):
        study = s.study
        return (study["date"], study["date"].replace("-", ""), study["accession"], study["id"], study["description"],
                study["uid"])

    def studied(keys):
        return [s for s in found if any(said.casefold() in {str(v).casefold() for v in keys(s) if v} and names(s, rest)
                                        for said, rest in splits)]

    matches = [s for s in found if names(s, text)]
    splits = [(text[:i].strip(), text[i + 1:].strip()) for i, c in enumerate(text) if c == "/"]
    return matches or studied(lambda s: (s.key,)) or studied(stored)


def _count(found):
    return f"{len(found)} DICOM series" if len(found) > 1 else "1 DICOM series"


def _listing(found):
    """The series listed, grouped by study where they come from several (as PACS viewers list them)."""
    if len({s.study["uid"] for s in found}) < 2:
        return "; ".join(s.shown() for s in found)
    studies = defaultdict(list)
    for s in found:
        studies[s.study["uid"]].append(s)
    return " | ".join(f"{group[0].study_shown()}: {'; '.join(s.shown() for s in group)}"
                      for group in studies.values())


def _named(found, series):
    """A series as a warning names it: with its study where the input holds several."""
    several = len({s.study["uid"] for s in found}) > 1
    return f"{series.shown()} of {series.study_shown()}" if several else series.shown()
