"""Which way the volume faces in a view (docs/viewer.md §4, "Orientation"): the letters at the image's edges, and the
sides the page's standard-view buttons name, both from the camera, here only.

A model whose world is a patient's RAS+ (its file's format places it so, or ``--orientation`` gave its axes) is
labelled as radiology labels it, R/L, A/P, S/I; any other (a phantom, a microscope stack, a simulation) by its world
axes, +x/−x, +y/−y, +z/−z, as napari and ParaView name them: those have no patient sides."""

from __future__ import annotations

import math

import numpy as np

from ..model.geometry import VIEWS, view_frame

#: the letters of +x, -x, +y, -y, +z, -z: a patient's (RAS+: x to their right, y anterior, z superior) or the axes'
PATIENT = (("R", "L"), ("A", "P"), ("S", "I"))
AXES = (("+x", "−x"), ("+y", "−y"), ("+z", "−z"))
#: a direction gets its second axis's letter where that component is at least this share of its largest: it is more
#: than 22.5 degrees from the nearest axis, nearer the diagonal between the two (two letters at most, as Slicer's)
SECOND = math.tan(math.radians(22.5))


def letters(direction, patient: bool) -> str:
    """The label of a world direction (x, y, z): its nearest axis's letter, then the next axis's where it is oblique
    (:data:`SECOND`), e.g. "AL" for a patient's front left, "+y−x" for the axes'."""
    names = PATIENT if patient else AXES
    d = np.asarray(direction, float)
    first, second = np.argsort(-np.abs(d), kind="stable")[:2]
    said = [first] + ([second] if abs(d[second]) >= SECOND * abs(d[first]) else [])
    return "".join(names[a][0 if d[a] > 0 else 1] for a in said)


def edges(camera, patient: bool) -> dict:
    """The labels of the image's ``left``, ``right``, ``top`` and ``bottom`` edges in ``camera``'s view: the
    directions ``-u``, ``u``, ``v``, ``-v`` of its frame (paper eq. 31, its roll too), from the image's centre
    towards each edge, in perspective as in orthographic projection."""
    _, u, v = camera.basis()
    return dict(left=letters(-u, patient), right=letters(u, patient), top=letters(v, patient),
                bottom=letters(-v, patient))


def views(patient: bool) -> dict:
    """The named views (:data:`~clwave.model.geometry.VIEWS`, the one table) for the page's buttons: each one's
    ``azimuth``, ``elevation`` and ``side``, the label of the side its camera looks from."""
    return {name: dict(azimuth=a, elevation=e, side=letters(view_frame(a, e)[0], patient))
            for name, (a, e) in VIEWS.items()}


def patient_world(wv, origin) -> bool:
    """Whether the served model's world is a patient's RAS+: ``clwave view`` was given ``--orientation``, or the
    file the model was made from (its ``provenance``, recorded since the twenty-third session) is of a format the
    loaders place in RAS+ (DICOM, NIfTI, NRRD, MGH).  A model of no file, or of a file no longer there, is not."""
    from ..io.loaders import in_ras

    if origin.get("orientation") is not None:
        return True
    return bool(wv.provenance) and in_ras(wv.provenance["file"])
