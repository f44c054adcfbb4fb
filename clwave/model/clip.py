"""Clipping: the part of world space a ray-traced image keeps (docs/coordinates.md §6, docs/raytracing.md §12): an
axis-aligned crop box and/or a few half-spaces, a convex region, so that a ray's interval through it is one
interval."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linprog

from ..errors import InputError, reals
from .geometry import voxel_box

MAX_PLANES = 6  #: half-spaces a clip takes (with the box: at most 12 faces to cut each ray at)
#: a region whose largest inscribed ball's radius is at most this fraction of its box's half-width along each axis
#: (:meth:`Clip.keeps`) keeps nothing (two planes with opposite normals through one point keep a plane, no volume)
THIN = 1e-9


@dataclass(frozen=True)
class Clip:
    """What a ray-traced image keeps, in world coordinates (RAS+, the volume's world units, docs/coordinates.md §6):
    the box ``lo`` .. ``hi`` (x, y, z corners, ``lo < hi``; None: no box) and the half-spaces ``planes``, each
    ``(point, normal)`` (a list, or an (n, 2, 3) array): the side the normal points to is kept, the plane itself
    included.  Validated when made
    (finite numbers, non-zero normals, at most :data:`MAX_PLANES` planes, a region with volume): one
    :class:`~clwave.InputError` naming the problem.  Taken by :func:`clwave.raytrace`, :meth:`RayTracer.render`
    and progressive ray tracing (``clip=``); changing it between renders rebuilds nothing.

    >>> Clip(planes=[((0, 0, 0), (1, 0, 0))]).contains([(1, 0, 0), (-1, 0, 0)]).tolist()
    [True, False]
    """

    lo: tuple | None = None
    hi: tuple | None = None
    planes: tuple = ()

    def __post_init__(self):
        if (self.lo is None) != (self.hi is None):
            raise InputError("a clip box needs both corners, lo and hi (x, y, z), or neither")
        if self.lo is not None:
            lo, hi = (tuple(reals(v, name, 3, "3 finite numbers (x, y, z) in world units").tolist())
                      for v, name in ((self.lo, "lo"), (self.hi, "hi")))
            _finite((*lo, *hi), f"the clip box's corners {lo} .. {hi}")
            if not all(a < b for a, b in zip(lo, hi)):
                raise InputError(f"the clip box's lo {lo} must be below its hi {hi} on every axis (x, y, z)")
            object.__setattr__(self, "lo", lo)
            object.__setattr__(self, "hi", hi)
        given = self.planes
        if isinstance(given, np.ndarray) and given.ndim == 3:  # (n, 2, 3): rows of (point, normal)
            given = list(given)
        if not isinstance(given, (list, tuple)):
            raise InputError(f"planes={given!r} must be a list of (point, normal), each 3 numbers (x, y, z)")
        if len(given) > MAX_PLANES:
            raise InputError(f"a clip takes at most {MAX_PLANES} planes, got {len(given)}")
        planes = []
        for i, plane in enumerate(given):
            if not (isinstance(plane, (list, tuple)) or isinstance(plane, np.ndarray) and plane.ndim) \
                    or len(plane) != 2:
                raise InputError(f"plane {i} {plane!r} must be (point, normal), each 3 numbers (x, y, z)")
            point, normal = (tuple(reals(v, f"plane {i}'s {name}", 3, "3 finite numbers (x, y, z)").tolist())
                             for v, name in zip(plane, ("point", "normal")))
            _finite((*point, *normal), f"plane {i}'s point {point} and normal {normal}")
            if not any(normal):
                raise InputError(f"plane {i}'s normal {normal} must be a non-zero direction (towards what is kept)")
            planes.append((point, normal))
        object.__setattr__(self, "planes", tuple(planes))
        if not self.lo and not planes:
            raise InputError("a clip needs a box (lo, hi) or at least one plane (point, normal)")
        if not self.keeps():
            raise InputError(f"{self.describe()} keeps nothing (no volume lies inside all of it): turn a plane's "
                             f"normal, or move a plane or the box")

    @classmethod
    def of_rows(cls, box, planes) -> "Clip":
        """The clip of rows of six numbers, as ``--clip-box`` / ``--clip-plane`` and the viewer's page give them:
        ``box`` x0, y0, z0, x1, y1, z1 (or None) and ``planes`` each px, py, pz, nx, ny, nz."""
        return cls(lo=box and box[:3], hi=box and box[3:], planes=[(p[:3], p[3:]) for p in planes])

    @classmethod
    def of_voxels(cls, model, voxels, orientation=None, planes=()) -> "Clip":
        """The clip of a box of voxels, in indices of the input array ``model`` (a :class:`~clwave.Volume` or
        :class:`~clwave.WaveletVolume`) was made of, as ``clwave info`` prints its shape: ``voxels`` three ranges in
        the array's axis order (z, y, x), "300:400,50:100,:" or ``[(300, 400), (50, 100), None]`` (STOP excluded, an
        end left out the array's); ``orientation`` the codes the input was loaded with (``clwave.load``'s, "RAI"),
        which turned its axes; ``planes`` as :class:`Clip`'s.  The box is the voxels' outer faces in world
        coordinates (:func:`~clwave.model.geometry.voxel_box`).  A model of a file placed in RAS+ by its header (NIfTI,
        DICOM, NRRD, MGH), whose array's axes were turned by it, is refused in one line."""
        from ..io.loaders import in_ras

        source = (getattr(model, "provenance", None) or {}).get("file")
        if source and in_ras(source):
            raise InputError(f"voxel ranges count the voxels of an input that carries no orientation (or the model's "
                             f"own array's); {source} was turned into RAS+ by its header, so its array's axes are not "
                             f"the model's: give a box in world coordinates (lo=, hi=; --clip-box)")
        lo, hi = voxel_box(voxels, model.shape[:3], model.spacing, model.origin, orientation)
        return cls(lo=lo, hi=hi, planes=planes)

    def half_spaces(self) -> np.ndarray:
        """The planes as rows ``(n_x, n_y, n_z, d)``, ``n`` a unit normal: the clip keeps ``n . x + d >= 0``
        (the box apart)."""
        rows = [(*n, -np.dot(n, p)) for p, n in ((np.array(p), _unit(n)) for p, n in self.planes)]
        return np.array(rows, float).reshape(-1, 4)

    def keeps(self, lo=None, hi=None) -> bool:
        """Whether the clip keeps some volume (within the box ``lo`` .. ``hi`` too, world (x, y, z), where given):
        the largest ball inside all of it, a linear program, has a radius above :data:`THIN`, in the coordinates that
        map the boxes' common part onto the cube [-1, 1]³ (else about the first plane's point, in units of the planes'
        largest distance from it): where the clip lies, how far its other faces are and how long the box is along
        its other axes (a slab) do not matter."""
        boxes = [(np.asarray(a, float), np.asarray(b, float)) for a, b in ((self.lo, self.hi), (lo, hi))
                 if a is not None]
        faces = self.half_spaces()
        normals = faces[:, :3]
        with np.errstate(over="ignore", invalid="ignore"):
            if boxes:
                b_lo, b_hi = np.max([b[0] for b in boxes], axis=0), np.min([b[1] for b in boxes], axis=0)
                centre, half = b_lo / 2 + b_hi / 2, b_hi / 2 - b_lo / 2  # halved first: no overflow at 1e308
                if not np.all(half > 0):
                    return False
                offsets = faces[:, 3] + normals @ centre  # the planes about the centre: n . x + offset >= 0
                normals = normals * half  # in the cube's coordinates (x - centre) / half; unit length below
                largest = np.abs(normals).max(axis=1, keepdims=True)  # divided by first: no overflow at 1e308
                normals = normals / largest
                length = np.linalg.norm(normals, axis=1, keepdims=True)
                normals = normals / length
                # beyond 4 from the centre a plane holds all or none of the cube (its corners lie within sqrt 3)
                offsets = np.clip(offsets / largest[:, 0] / length[:, 0], -4.0, 4.0)
            else:
                offsets = faces[:, 3] + normals @ np.array(self.planes[0][0], float)
                offsets = offsets / (np.abs(offsets).max(initial=0.0) or 1.0)
        rows = [(*-n, 1.0) for n in normals]  # n . x + offset >= r  <=>  -n . x + r <= offset
        bounds = list(offsets)
        for a in range(3 if boxes else 0):
            axis = np.eye(3)[a]
            rows += [(*-axis, 1.0), (*axis, 1.0)]
            bounds += [1.0, 1.0]
        best = linprog(c=(0, 0, 0, -1), A_ub=np.array(rows, float).reshape(-1, 4), b_ub=np.array(bounds, float),
                       bounds=[(None, None)] * 3 + [(None, 1.0)], method="highs")
        return bool(best.status == 0 and -best.fun > THIN)

    def contains(self, points) -> np.ndarray:
        """Per world point (N, 3) as (x, y, z): whether the clip keeps it."""
        x = np.atleast_2d(np.asarray(points, float))
        inside = np.ones(len(x), bool)
        if self.lo is not None:
            inside &= np.all((x >= self.lo) & (x <= self.hi), axis=1)
        for h in self.half_spaces():
            inside &= x @ h[:3] + h[3] >= 0
        return inside

    def describe(self) -> str:
        """The clip in words, for messages."""
        parts = [f"box {list(self.lo)} .. {list(self.hi)}"] if self.lo is not None else []
        parts += [f"plane through {list(p)} keeping normal {list(n)}" for p, n in self.planes]
        return "the clip (" + "; ".join(parts) + ")"


def _unit(normal) -> np.ndarray:
    """``normal`` scaled to length 1 (by its largest component first: 1e200 or 1e-200 is as good a length as 1)."""
    n = np.array(normal, float)
    n /= np.abs(n).max()
    return n / np.linalg.norm(n)


def _finite(values, what):
    if not np.all(np.isfinite(values)):
        raise InputError(f"{what} must be finite numbers")


def check_clip(clip) -> Clip | None:
    """``clip=`` of a render: None or a :class:`Clip` (InputError naming the argument otherwise)."""
    if clip is not None and not isinstance(clip, Clip):
        raise InputError(f"clip={clip!r} must be a clwave.Clip(lo=, hi=, planes=) or None")
    return clip
