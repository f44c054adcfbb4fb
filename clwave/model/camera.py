"""Camera: orthographic (default) or perspective views set by azimuth and elevation.

Paper eq. 31, world (x, y, z), angles in degrees:
``n = (cos a cos b, sin a cos b, sin b)``, ``u = (-sin a, cos a, 0)``,
``v = (-cos a sin b, -sin a sin b, cos b)``; ``u x v = n``.  The camera sits on
the ``+n`` side looking along ``-n``; u points right and v up in the image, so
images are not mirrored.  Pixel ``(row r, col c)`` has its centre at
``target + (c + 0.5 - W/2) p u + (H/2 - r - 0.5) p v`` with ``p = extent / W``.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import product

import numpy as np

from ..device.memory import check_image
from ..errors import ClwaveWarning, InputError, finite_number, flag, reals, warn_outside, whole_number
from .geometry import WORLD_RANGE, view_frame

#: The most pixels across the content box's diagonal: the splat kernels' float32 steps grow as its reciprocal (an
#: extent of 1e-40 overflowed them and crashed; 1e-320, a pixel of 0, was an internal error), while a millionth of a
#: voxel still renders from the band's textures (tests/test_hardening.py)
MAX_PIXELS_ACROSS = 10**12
#: the largest extent and distance (world units): the world lengths clwave renders
FARTHEST = WORLD_RANGE[1]

FITS = ("sphere", "box")  #: a camera's default framings of the content (Camera's ``fit``)
OPENING = (30.0, 20.0)  #: the default (azimuth, elevation), degrees
#: a content box whose shortest side is under 1 / SLAB of its middle one is a slab, which opens showing its face
SLAB = 3.0
#: the opening (azimuth, elevation) of a slab thin along x, y or z: looking down that axis, 20 degrees off it so that
#: it reads as a solid, with x to the right where the axis is y or z (z: y up, as IMOD's 3dmod and ChimeraX show it)
SLAB_VIEWS = ((20.0, 20.0), (-70.0, 20.0), (-70.0, 70.0))
#: a photo stack's slab thin along z opens from -z, y down: its row 0 at the top, as image viewers show a photo
#: (docs/coordinates.md §1, "Which view shows a slice as photographed"; from +z it reads upside down)
PHOTO_SLAB_VIEW = (-70.0, -70.0)
DEFAULT_FOV = 30.0  #: a perspective camera's vertical field of view, degrees, unless given
#: how many times longer than its two shorter sides a content box is at most before a view of it warns: a needle
#: that every view shows as a line a few pixels wide, or nothing (axes in different units, trial26)
NEEDLE = 100.0


@dataclass(frozen=True)
class View:
    """A camera resolved against a volume: everything a renderer needs, float64."""

    n: np.ndarray        # (3,) towards the camera
    u: np.ndarray        # (3,) image right
    v: np.ndarray        # (3,) image up
    target: np.ndarray   # (3,) world point at the image centre
    size: tuple          # (H, W)
    pixel: float         # world width of a pixel
    perspective: bool
    eye: np.ndarray      # (3,) eye position (perspective only)
    fov: float           # vertical field of view in degrees (perspective only)
    #: perspective: ray slopes (along u, along v) per pixel, and the slopes of the image centre's ray
    #: (docs/coordinates.md §5); the ray of slopes (s_u, s_v) leaves the eye along -n + s_u u + s_v v
    slope: tuple = None
    principal: tuple = (0.0, 0.0)

    def to_pixels(self, points_xyz) -> np.ndarray:
        """Projection of world points to continuous (col, row) pixel coordinates (orthographic, or
        through the eye onto the detector where perspective)."""
        H, W = self.size
        if self.perspective:
            d = np.asarray(points_xyz, float) - self.eye
            depth = -(d @ self.n)
            col = (d @ self.u / depth - self.principal[0]) / self.slope[0] + W / 2.0 - 0.5
            row = H / 2.0 - 0.5 - (d @ self.v / depth - self.principal[1]) / self.slope[1]
            return np.stack([col, row], axis=-1)
        d = np.asarray(points_xyz, float) - self.target
        col = d @ self.u / self.pixel + W / 2.0 - 0.5
        row = H / 2.0 - 0.5 - d @ self.v / self.pixel
        return np.stack([col, row], axis=-1)

    def depth(self, points_xyz) -> np.ndarray:
        """Perspective: the distance of world points from the eye along the view axis -n."""
        return -((np.asarray(points_xyz, float) - self.eye) @ self.n)

    def slopes(self) -> np.ndarray:
        """Perspective: the ray slopes ``(s_u, s_v)`` of every pixel centre, (H, W, 2)."""
        H, W = self.size
        su = self.principal[0] + (np.arange(W) + 0.5 - W / 2.0) * self.slope[0]
        sv = self.principal[1] + (H / 2.0 - np.arange(H) - 0.5) * self.slope[1]
        return np.stack(np.broadcast_arrays(su[None, :], sv[:, None]), axis=-1)

    def rays(self) -> np.ndarray:
        """Perspective: the unit direction of every pixel's ray from the eye, (H, W, 3)."""
        s = self.slopes()
        d = -self.n + s[..., :1] * self.u + s[..., 1:] * self.v
        return d / np.linalg.norm(d, axis=-1, keepdims=True)

    def obliquity(self) -> np.ndarray:
        """Perspective: the path length per unit depth of every pixel's ray, ``sqrt(1 + s_u^2 + s_v^2)``, (H, W)."""
        return np.sqrt(1.0 + np.sum(self.slopes() ** 2, axis=-1))

    def pixel_centres(self) -> np.ndarray:
        """World centres of all pixels, (H, W, 3)."""
        H, W = self.size
        c = (np.arange(W) + 0.5 - W / 2.0) * self.pixel
        r = (H / 2.0 - np.arange(H) - 0.5) * self.pixel
        return self.target + r[:, None, None] * self.v + c[None, :, None] * self.u


class Camera:
    """A view of a volume (docs/coordinates.md §2).

    Parameters
    ----------
    azimuth, elevation : float
        Degrees; the direction from the target towards the camera (paper eq. 31).
    size : int or (H, W)
        Image size in pixels.
    target : (x, y, z), optional
        World point at the image centre; default the centre of the content's bounding sphere.
    extent : float, optional
        World width of the image; default by ``fit``.  The content is where the model (or volume)
        is non-zero (``content_box()``), else its voxel box.
    fit : ``"sphere"`` or ``"box"``
        The default framing: ``"sphere"`` (default), the content's bounding sphere fills the image's
        shorter side, the same at every view (a turntable keeps its framing); ``"box"``, the content
        box's projection for this view fills the image, touching its edge (an elongated volume seen
        from its side fills the image, where the sphere leaves most of it empty).
    perspective, distance, fov :
        Perspective projection: eye at ``target + distance * n``, vertical field of view ``fov``
        degrees (a cone beam whose detector is centred on the axis; :class:`clwave.ConeBeam` for others).
        With ``fit="box"`` the default distance is the least at which the box's corners are in view.
        ``distance`` and ``fov`` (default 30) without ``perspective`` are refused: they would change nothing.
    roll : float
        Degrees the camera turns about its view axis (default 0): u and v turned by ``roll`` towards each other, the
        picture so turned clockwise; with the angles, any orientation (a turntable about another axis than z,
        :meth:`rotated`).

    Examples
    --------
    >>> cam = Camera(azimuth=0, elevation=0, size=4)
    >>> cam.basis()[0].tolist()  # n
    [1.0, 0.0, 0.0]
    """

    def __init__(self, azimuth=OPENING[0], elevation=OPENING[1], size=512, *, target=None, extent=None,
                 perspective=False, distance=None, fov=None, fit="sphere", roll=0.0):
        self.azimuth = finite_number(azimuth, "azimuth")
        self.elevation = finite_number(elevation, "elevation")
        self.roll = finite_number(roll, "roll")
        self.size = _size(size)
        self.target = None if target is None else _vector(target, "target")
        # at most the world lengths clwave renders (geometry.WORLD_RANGE): an eye 1e308 away hung the ray tracer
        if extent is not None and not 0 < finite_number(extent, "extent") <= FARTHEST:
            raise InputError(f"extent={extent!r} must be a positive world width up to {FARTHEST:g}",
                             cli=f"--extent {extent} must be a positive world width up to {FARTHEST:g}")
        self.extent = None if extent is None else float(extent)
        self.perspective = flag(perspective, "perspective")
        if distance is not None and not 0 < finite_number(distance, "distance") <= FARTHEST:
            raise InputError(f"distance={distance!r} must be a positive world distance up to {FARTHEST:g}",
                             cli=f"--distance {distance} must be a positive world distance up to {FARTHEST:g}")
        self.distance = None if distance is None else float(distance)
        if fov is not None and not 0 < finite_number(fov, "fov") < 180:
            raise InputError(f"fov={fov!r} must be between 0 and 180 degrees",
                             cli=f"--fov {fov} must be between 0 and 180 degrees")
        self.fov = DEFAULT_FOV if fov is None else float(fov)
        unused = [name for name, value in (("fov", fov), ("distance", distance)) if value is not None]
        if unused and not self.perspective:  # an orthographic view has neither: refused, never ignored
            them = " and ".join(unused)
            raise InputError(f"{them}= set{'s' * (len(unused) == 1)} a perspective camera's view: give "
                             f"perspective=True too, or leave {them}= out",
                             cli=f"{' and '.join('--' + n for n in unused)} set{'s' * (len(unused) == 1)} a "
                                 f"perspective view: add --perspective, or leave {'them' if len(unused) > 1 else 'it'} "
                                 f"out")
        if fit not in FITS:
            raise InputError(f"fit={fit!r} must be 'sphere' or 'box'", cli=f"--fit {fit} must be sphere or box")
        given = "distance" if perspective and distance is not None else "extent" if extent is not None else None
        if fit == "box" and given:
            raise InputError(f"fit='box' sets the {given} that {given}= sets: give one of them",
                             cli=f"--fit box sets the --{given}: give one of them")
        self.fit = fit

    def basis(self):
        """``(n, u, v)`` of paper eq. 31 as float64 arrays."""
        n, u, v = view_frame(self.azimuth, self.elevation)
        if self.roll:
            c, s = np.cos(np.radians(self.roll)), np.sin(np.radians(self.roll))
            u, v = c * u + s * v, c * v - s * u
        # exact zeros keep axis-aligned views exact (cos 90 deg is 6e-17)
        return tuple(np.where(np.abs(x) < 1e-15, 0.0, x) for x in (n, u, v))

    def view(self, volume) -> View:
        """Resolve against a volume-like object (``shape``, ``spacing``, ``origin``)."""
        n, u, v = self.basis()
        H, W = self.size
        lo, hi = framed_box(volume)
        _warn_needle(hi - lo)
        target = (lo + hi) / 2.0 if self.target is None else np.asarray(self.target)
        corners = np.array(list(product(*zip(lo, hi)))) - target
        slope = 2.0 * np.tan(np.radians(self.fov) / 2.0) / H  # perspective: square pixels, the centre on the axis
        if self.fit == "box":  # the corners' farthest projections on the image edges (docs/coordinates.md §2)
            across = np.abs(corners @ np.stack([u, v], axis=1)) / np.array([W, H])  # per corner, per image pixel
            extent = 2.0 * W * float(across.max())
            # perspective: corner c, at depth D - c.n from the eye, is in view while |c.u| / (D - c.n) <= slope W / 2
            # and |c.v| / (D - c.n) <= slope H / 2; the least such D over the corners
            distance = float(np.max(corners @ n + 2.0 * across.max(axis=1) / slope)) if self.perspective \
                else 2.0 * extent
        else:  # the sphere about the target holding the content box, across the image's shorter side
            extent = self.extent or 2.0 * float(np.max(np.linalg.norm(corners, axis=1))) * W / min(H, W)
            distance = self.distance or 2.0 * extent
        pixel = slope * distance if self.perspective else extent / W
        if not pixel * MAX_PIXELS_ACROSS >= float(np.linalg.norm(hi - lo)):  # also a pixel of 0 or NaN
            what = "distance" if self.perspective else "extent"
            raise InputError(f"{what}={distance if self.perspective else extent:g} makes a pixel of {pixel:.3g} world "
                             f"units, too small for the volume (at most {MAX_PIXELS_ACROSS:.0e} pixels across it: the "
                             f"kernels' float32 steps); give a larger {what}",
                             cli=f"--{what} makes a pixel too small for the volume (at most {MAX_PIXELS_ACROSS:.0e} "
                                 f"pixels across it: the kernels' float32 steps): give a larger --{what}")
        if not self.perspective:
            return View(n, u, v, target, (H, W), pixel, False, target + distance * n, self.fov)
        return View(n, u, v, target, (H, W), pixel, True, target + distance * n, self.fov, (slope, slope), (0.0, 0.0))

    def reduced(self, reduction: int, view: View) -> "Camera":
        """The same view with ``reduction`` times larger pixels (sides rounded up, the same centre): a progressive
        frame's reduced image. ``view``: this camera's :meth:`view` of the volume, which fixes what the camera
        leaves to the volume (target, extent, distance)."""
        H, W = self.size
        h, w = -(-H // reduction), -(-W // reduction)
        fov = self.fov
        if self.perspective:
            s = 2.0 * np.tan(np.radians(view.fov) / 2.0) / H * reduction  # image-plane units per reduced pixel
            fov = float(np.degrees(2.0 * np.arctan(s * h / 2.0)))
        perspective = dict(perspective=True, distance=float(np.linalg.norm(view.eye - view.target)), fov=fov) \
            if self.perspective else {}
        return Camera(self.azimuth, self.elevation, size=(h, w), target=view.target, extent=view.pixel * reduction * w,
                      roll=self.roll, **perspective)

    def rotated(self, degrees, axis=None) -> "Camera":
        """The same camera turned by ``degrees`` about ``axis`` (turntables), right-handed: a unit (x, y, z) vector,
        None for z (the azimuth turned, the elevation and roll kept); another axis gives the angles and roll of the
        turned frame (n, u, v)."""
        cam = Camera.__new__(Camera)
        cam.__dict__.update(self.__dict__)
        if axis is None:
            cam.azimuth = self.azimuth + float(degrees)
            return cam
        k, t = np.asarray(axis, float), np.radians(float(degrees))  # Rodrigues' formula of the turned n and u
        n, u = ((x * np.cos(t) + np.cross(k, x) * np.sin(t) + k * (k @ x) * (1 - np.cos(t))) for x in self.basis()[:2])
        cam.azimuth = float(np.degrees(np.arctan2(n[1], n[0])))
        cam.elevation = float(np.degrees(np.arcsin(np.clip(n[2], -1.0, 1.0))))
        _, u0, v0 = view_frame(cam.azimuth, cam.elevation)
        cam.roll = float(np.degrees(np.arctan2(u @ v0, u @ u0)))
        return cam

    def to_dict(self) -> dict:
        """JSON-safe description of the camera as given (what it leaves to the volume stays None);
        ``Camera.from_dict(to_dict())`` re-makes it exactly."""
        return dict(kind="camera", azimuth=self.azimuth, elevation=self.elevation, size=list(self.size),
                    target=None if self.target is None else [float(x) for x in self.target], extent=self.extent,
                    perspective=self.perspective, distance=self.distance, fov=self.fov if self.perspective else None,
                    fit=self.fit, roll=self.roll)

    @classmethod
    def from_dict(cls, d) -> "Camera":
        """Inverse of :meth:`to_dict` (a render's ``meta["camera"]``, docs/coordinates.md §4); absent fields take
        their defaults."""
        return cls(**given_fields(d, "camera", cls.to_dict(cls()), "Camera"))

    def __repr__(self):
        """Valid Python that makes this camera: every field that is not its default."""
        return f"Camera({arguments(self.to_dict(), Camera().to_dict(), first=('azimuth', 'elevation', 'size'))})"


def given_fields(d, kind, fields, name) -> dict:
    """The arguments in ``d``, a ``to_dict()`` of a camera of this ``kind`` (``name``'s, of ``fields``), checked
    against the fields it may hold: one line naming what is wrong (a file's camera is untrusted)."""
    if not isinstance(d, dict) or d.get("kind", kind) != kind:
        found = d.get("kind") if isinstance(d, dict) else type(d).__name__
        raise InputError(f"a {name} description must be a dict of kind {kind!r} as {name}.to_dict() writes, "
                         f"not {found!r}")
    unknown = sorted(set(d) - set(fields), key=str)
    if unknown:
        raise InputError(f"a {name} description has unknown field(s) {', '.join(map(str, unknown))}; "
                         f"it takes {', '.join(k for k in fields if k != 'kind')}")
    return {k: tuple(v) if isinstance(v, list) else v for k, v in d.items() if k != "kind"}


def arguments(fields: dict, defaults: dict, first=()) -> str:
    """``name=value, ...`` of the ``fields`` (a ``to_dict()``) that differ from ``defaults``, and of ``first``
    always: a repr's arguments, lists as tuples."""
    shown = [k for k in fields if k != "kind" and (k in first or fields[k] != defaults.get(k))]
    return ", ".join(f"{k}={tuple(fields[k]) if isinstance(fields[k], list) else fields[k]!r}" for k in shown)


def _size(size) -> tuple:
    hw = list(size) if isinstance(size, (tuple, list)) else list(np.ravel(size))  # a bool or a string is no size
    if len(hw) == 1:
        hw *= 2
    if len(hw) != 2 or not all(whole_number(n) and n >= 1 for n in hw):
        raise InputError(f"image size {size!r} must be a positive whole number or (H, W)")
    hw = int(hw[0]), int(hw[1])
    check_image(None, hw, 0, "give a smaller size= (at most {n}x{n} here)")  # the host's share: refused before a device
    return hw


def _vector(value, name) -> np.ndarray:
    arr = reals(value, name, 3, "three finite numbers (x, y, z)")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{name}={value!r} must be three finite numbers (x, y, z)")
    return arr


def _warn_needle(sides) -> None:
    """A :class:`ClwaveWarning` where the content box's ``sides`` (x, y, z) are a needle (:data:`NEEDLE`), naming the
    spacing: every view of it is a line or a dot, with no hint where its axes' spacings are in different units."""
    short, middle, long = sorted(sides)
    if not middle * NEEDLE < long:
        return
    line = (f"the content's box is {' x '.join(f'{s:.3g}' for s in sides)} (x, y, z), {long / middle:.3g} times longer "
            f"than wide: an image of it is a line a few pixels wide, or nothing; if its axes are in different units "
            f"(e.g. m/s against degrees), give ")
    warn_outside(ClwaveWarning(line + "the volume a spacing= in one unit (e.g. spacing=1)",
                               cli=line + "--spacing in one unit (e.g. --spacing 1; a .clw: compress it again so)"))


def framed_box(volume) -> tuple:
    """World ``(lo, hi)`` of what a camera frames by default: a model's content (:func:`_content_box`) cut to where its
    approximation stands above the noise (:attr:`~clwave.WaveletVolume.signal_box`), so that the noise of an empty part
    of the box is not framed (docs/coordinates.md §2)."""
    lo, hi = _content_box(volume)
    signal = getattr(volume, "signal_box", None)
    if signal is None:
        return lo, hi
    cut_lo, cut_hi = np.maximum(lo, signal[0]), np.minimum(hi, signal[1])
    return (cut_lo, cut_hi) if np.all(cut_lo < cut_hi) else (lo, hi)


def opening_view(volume) -> dict:
    """``dict(azimuth=, elevation=)`` a volume opens at where no view is given: a slab's face where the shortest side of
    its :func:`framed_box` is under 1 / :data:`SLAB` of the middle one (a tomogram, a section stack, seen down its
    thin axis as IMOD opens it; a photo stack's as image viewers show it, :data:`PHOTO_SLAB_VIEW`), else
    :data:`OPENING`."""
    lo, hi = framed_box(volume)
    sides = hi - lo
    thin = int(np.argmin(sides))
    if sides[thin] * SLAB >= np.sort(sides)[1]:
        azimuth, elevation = OPENING
    else:
        azimuth, elevation = PHOTO_SLAB_VIEW if thin == 2 and getattr(volume, "photo", False) else SLAB_VIEWS[thin]
    return dict(azimuth=azimuth, elevation=elevation)


def _content_box(volume) -> tuple:
    """World ``(lo, hi)`` of a volume-like object's content, or of its voxel box."""
    box = volume.content_box() if hasattr(volume, "content_box") else None
    if box is not None:
        return np.asarray(box[0], float), np.asarray(box[1], float)
    half = np.array(volume.shape[::-1], float) * np.array(volume.spacing[::-1], float) / 2.0
    return np.asarray(volume.origin, float) - half, np.asarray(volume.origin, float) + half
