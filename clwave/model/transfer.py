"""Transfer functions: pre-classification of scalar volumes to ``(q_R, q_G, q_B, alpha)`` before the
wavelet transform (paper §2.2, docs/model.md §5), so a new transfer function means a new transform.

>>> tf = TransferFunction([(0.0, 0, 0, 1, 0.0), (1.0, 1, 0, 0, 0.1)])
>>> rgb, alpha = tf([0.5])
>>> rgb.tolist(), alpha.tolist()
([[0.5, 0.0, 0.5]], [0.05])
"""

from __future__ import annotations

import numpy as np

from ..errors import ClwaveWarning, InputError, NearlyOpaqueWarning, NothingVisibleError, warn_outside
from .colour_key import DEFAULT_TOLERANCE, auto_key, check_key, key_weight
from .tf_checks import check_opacity_unit, check_points, check_window, not_hounsfield
from .tf_passes import AUTO_SAMPLES, PiecewiseLinear, auto_window, classified, rgb_scale, scan
from .tf_presets import PRESETS as _PRESETS, colormap_named, colormap_points
from .volume import Volume

#: Rec. 601 luma weights used for the opacity of RGB(A) volumes.
LUMA = (0.299, 0.587, 0.114)
#: a classification warns (nearly opaque) where the median voxel's optical depth across one voxel reaches OPAQUE_VOXEL,
#: or the median voxel of the box's faces' across the box's thinnest side OPAQUE_BOX (transmittance e^-5, 0.7 %)
#: (docs/model.md §5)
OPAQUE_VOXEL = 1.0
OPAQUE_BOX = 5.0
#: and nearly transparent where no ray along the box's axes reaches an optical depth of TRANSPARENT_RAY (78 % of the
#: light through every one: a faint or black picture, docs/model.md §5)
TRANSPARENT_RAY = 0.25

_FORMAT = "clwave-transfer-function"


class TransferFunction:
    """Piecewise-linear map from scalar value to emission colour and opacity.

    Pre-classification (paper §2.2): apply it with :meth:`classify` *before*
    ``WaveletVolume.from_volume``; a different transfer function needs a new
    classification and a new wavelet transform.

    Parameters
    ----------
    points : sequence of (value, r, g, b, opacity)
        At least 2 rows; values finite and strictly increasing; r, g, b in
        [0, 1]; opacity >= 0, the extinction per ``opacity_unit`` of length.  Between
        points everything is interpolated linearly; outside, the end rows hold.
    window : None, "auto" or (lo, hi)
        ``None``: point values are data values.  Otherwise point values live on
        a normalised axis that the window maps to data units, 0 -> lo and
        1 -> hi; ``"auto"`` takes (lo, hi) from the 0.5 and 99.5 percentiles of
        the finite values being classified.  Data units are the input's (HU
        for CT): on a volume or model with a value ``subtracted`` (values stored
        as the input's minus it, ``load(subtract=)``) the function is applied
        shifted by it (:meth:`shifted`), so the same function classifies alike
        with or without ``subtract=``.
    name : str, optional
        A label (presets carry their name); kept by :meth:`to_dict`.
    opacity_unit : None or float
        The length (world units) the opacities are per: the extinction per world unit is opacity / opacity_unit
        (:meth:`extinction`).  ``None``: one voxel, the smallest spacing of the volume classified, so a volume looks
        the same whatever its length unit (µm or mm) and one of spacing 1 as per world unit (docs/model.md §5).
    key : None, "auto", (r, g, b) or (r, g, b, tolerance)
        A colour volume's background colour, in its sample units (0 .. 255 for 8 bits): a voxel within the tolerance
        of it (default 0.1 of the colour's range) gets no opacity, one beyond twice it all its opacity, linearly between
        (:func:`~clwave.model.colour_key.key_weight`); "auto": the median colour of the box's edges.  None: no key.

    Examples
    --------
    >>> tf = TransferFunction.preset("ct-bone")              # window (-1000, 2000) HU
    >>> tf.window
    (-1000.0, 2000.0)
    >>> rgba = tf.classify(Volume(np.full((4, 4, 4), 1000.0)))   # (q_R, q_G, q_B, alpha)
    >>> float(rgba.data[0, 0, 0, 3])
    0.5
    """

    #: Names accepted by :meth:`preset`.
    PRESETS = tuple(_PRESETS)

    def __init__(self, points, window=None, name=None, opacity_unit=None, key=None):
        self._points = check_points(points)
        self._key = check_key(key)
        self._window = check_window(window)
        self._unit = check_opacity_unit(opacity_unit)
        if name is not None and not isinstance(name, str):
            raise InputError(f"transfer function name must be a string or None, got {name!r}")
        self.name = name

    # ----------------------------------------------------------------- construction
    @classmethod
    def preset(cls, name, window=None, opacity_unit=None) -> "TransferFunction":
        """A named preset; ``window`` None keeps its default, else "auto" or (lo, hi); ``opacity_unit`` as the
        constructor's (None: one voxel).

        ============== ================== ==========================================
        name           default window     opacity (per opacity unit: a voxel)
        ============== ================== ==========================================
        ct-bone        (-1000, 2000) HU   0 to +150 HU, 0.1 at +300, 0.5 from +700
        ct-soft-tissue (-1000, 1000) HU   0 to -200 HU, 0.01 at -100 (fat), 0.03 at +40
                                          (muscle), 0.05 at +300, 0.3 at +1000 (bone)
        mri            auto               0 to 0.1, 0.01 / 0.03 / 0.06 at 0.3 / 0.6 / 1
        hydrogen       (0, 1)             0 to 0.05, 0.02 / 0.05 / 0.1 at 0.25 / 0.55 / 1
        grey           auto               linear 0 .. 0.05, colour black .. white
        brightfield    auto               0.3 at 0 falling to 0 at 0.9 (white), of
                                          the luminance of a colour volume, coloured
                                          by its own RGB (stained sections, photos)
        photo          (0, 1)             0.5 times a colour volume's own alpha (1
                                          without one), coloured by its own RGB
        ============== ================== ==========================================
        """
        key = name.strip().lower().replace("_", "-") if isinstance(name, str) else None
        if key == "gray":
            key = "grey"
        if key not in _PRESETS:
            what = f"unknown transfer function preset {name!r}; choose one of {', '.join(cls.PRESETS)}"
            hint = f" (a matplotlib colormap: TransferFunction.from_colormap({name!r}))" if colormap_named(name) else ""
            raise InputError(what + hint, cli=what)
        spec = _PRESETS[key]
        return cls(spec["points"], window=spec["window"] if window is None else window, name=key,
                   opacity_unit=opacity_unit)

    @classmethod
    def from_colormap(cls, cmap, opacity=(0.0, 0.05), window="auto", opacity_unit=None) -> "TransferFunction":
        """A matplotlib colormap (a ``Colormap``, or its name) as a function: the colormap's colours over the window
        ("auto", or (lo, hi) as the constructor's), the opacity rising linearly from ``opacity[0]`` to ``opacity[1]``
        across it (per opacity unit; the default as the grey preset's) times the colormap's own alpha.  The ``N``
        colours are points evenly spread over the window, linear between: a colormap of few colours (``tab10``)
        blends its neighbours where matplotlib shows each in its own bin; for categories use :meth:`labels`.

        >>> import matplotlib
        >>> tf = TransferFunction.from_colormap(matplotlib.colormaps["gray"], window=(0, 10))
        >>> rgb, alpha = tf([5.0])
        >>> rgb.round(2).tolist(), alpha.round(3).tolist()
        ([[0.5, 0.5, 0.5]], [0.025])
        """
        points, name = colormap_points(cmap, opacity)
        return cls(points, window=window, name=name, opacity_unit=opacity_unit)

    @classmethod
    def labels(cls, colours, name="labels") -> "TransferFunction":
        """A categorical function for a label map (docs/model.md §5): ``colours`` maps each shown label (a whole
        number) to ``(r, g, b, opacity)``; a label's row holds from ``label - 0.5`` to ``label + 0.5`` (steps
        :data:`LABEL_EDGE` wide at the halves), every other value is transparent.  A Haar model of a label map takes
        its labels exactly; one of higher order interpolates between them, showing labels that are not there.

        >>> tf = TransferFunction.labels({1: (1, 0, 0, 0.5), 3: (0, 0, 1, 2.0)})
        >>> tf([0, 1, 2, 3, 3.4])[1].tolist()
        [0.0, 0.5, 0.0, 2.0, 2.0]
        """
        if not isinstance(colours, dict) or not colours:
            raise InputError("TransferFunction.labels takes a dict {label: (r, g, b, opacity)} of at least one label")
        shown = {}
        for label, colour in colours.items():
            if not _whole(label):
                raise InputError(f"label {label!r} is not a whole number; labels are the integers of a label map")
            try:
                shown[int(float(label))] = [float(c) for c in colour]
            except (TypeError, ValueError, OverflowError):  # OverflowError: an integer past float's range
                shown[int(float(label))] = []
            if len(shown[int(float(label))]) != 4:
                raise InputError(f"label {label}'s colour {colour!r} must be 4 numbers (r, g, b, opacity)")
        rows = []
        for label in sorted(shown):
            colour, clear = shown[label], shown[label][:3] + [0.0]
            if label - 1 not in shown:  # transparent below the step
                rows.append([label - 0.5 - LABEL_EDGE] + clear)
            rows += [[label - 0.5 + LABEL_EDGE] + colour, [label + 0.5 - LABEL_EDGE] + colour]
            if label + 1 not in shown:
                rows.append([label + 0.5 + LABEL_EDGE] + clear)
        return cls(rows, name=name)

    # ----------------------------------------------------------------- properties
    @property
    def points(self) -> np.ndarray:
        """Control points (K, 5) ``(value, r, g, b, opacity)``, read-only float64."""
        return self._points

    @property
    def window(self):
        """None, "auto" or (lo, hi)."""
        return self._window

    @property
    def opacity_unit(self):
        """None (one voxel) or the length in world units that the opacities are per."""
        return self._unit

    @property
    def key(self):
        """None, "auto" or the colour key (r, g, b, tolerance or None), in the volume's sample units."""
        return self._key

    def under(self, window=..., opacity_unit=..., key=...) -> "TransferFunction":
        """This function with another ``window``, ``opacity_unit`` and/or ``key`` (``...``: its own), points and name
        kept."""
        return TransferFunction(self._points, self._window if window is ... else window, self.name,
                                self._unit if opacity_unit is ... else opacity_unit, self._key if key is ... else key)

    def extinction(self, spacing) -> np.ndarray:
        """The points' opacities as extinction per world unit on a volume or model of ``spacing``: opacity /
        opacity_unit, the unit one voxel (the smallest spacing) where None; the one place a transfer function's
        opacity becomes the extinction that pre- and post-classification integrate (docs/model.md §5)."""
        return self._points[:, 4] / (float(min(spacing)) if self._unit is None else self._unit)

    def resolve_window(self, values=None):
        """The window in data units: None, (lo, hi), or for "auto" the percentiles of ``values``."""
        if self._window != "auto":
            return self._window
        if values is None:
            raise InputError('window "auto" needs the values to be classified; '
                             "pass them, or give a window (lo, hi)")
        return auto_window(values)

    def data_points(self, window=...) -> np.ndarray:
        """Point values in data units under ``window`` (default: this function's own)."""
        win = self._window if window is ... else check_window(window)
        if win == "auto":
            raise InputError('window "auto" needs data; call resolve_window(values) first')
        t = self._points[:, 0]
        return t.copy() if win is None else win[0] + t * (win[1] - win[0])

    def shifted(self, subtracted) -> "TransferFunction":
        """This function for values stored as the input's minus ``subtracted`` (:attr:`Volume.subtracted`): its window,
        or its points where it has none, moved by -subtracted; a window "auto" (percentiles of the values met) stays."""
        if not subtracted or self._window == "auto":
            return self
        given = self._points[:, 0] if self._window is None else np.array(self._window)
        moved = given - subtracted
        merged = np.flatnonzero(np.diff(moved) <= 0)  # closer than float64 tells apart where the subtraction moves them
        if merged.size:
            i = int(merged[0])
            raise InputError(f"transfer function {'values' if self._window is None else 'window'} {given[i]:g} and "
                             f"{given[i + 1]:g} merge on the model's values, stored as the input's minus the value "
                             f"subtracted, {subtracted:g}; set them at least "
                             f"{2 * np.spacing(np.abs(moved[i:i + 2]).max()):.2g} apart")
        if self._window is None:
            return TransferFunction(np.column_stack([moved, self._points[:, 1:]]), name=self.name,
                                    opacity_unit=self._unit, key=self._key)
        return self.under(tuple(moved))

    def _on(self, vol, window) -> "TransferFunction":
        """This function under ``window`` (``...``: its own) in the units of ``vol``'s data: a scalar's shifted by the
        value subtracted from it (a colour volume's points are on luminance)."""
        tf = self.under(window)._keyed(vol)
        return tf.shifted(vol.subtracted) if vol.channels == 1 else tf

    def _keyed(self, vol) -> "TransferFunction":
        """This function with a key "auto" found in ``vol``; a key on a scalar volume refused."""
        if self._key is not None and vol.channels == 1:
            raise InputError("a colour key applies to a colour (RGB or RGBA) volume; this one is scalar: leave it out",
                             cli="--key applies to a colour (RGB or RGBA) input; this one is scalar: leave it out")
        return self.under(key=auto_key(vol.data)) if self._key == "auto" else self

    # ----------------------------------------------------------------- evaluation
    def __call__(self, values, window=...):
        """Colour and opacity of scalar ``values``.

        Parameters
        ----------
        values : array_like
            Scalar data values, any shape, in the function's units (of values stored with a value subtracted:
            :meth:`shifted`).
        window : optional
            Overrides this function's window (None, "auto" or (lo, hi)); "auto"
            is resolved against ``values`` themselves.

        Returns
        -------
        rgb : ndarray (..., 3) float64, in [0, 1]
        alpha : ndarray (...) float64, opacity per :attr:`opacity_unit` (as the points give it)
        """
        v = np.asarray(values, dtype=np.float64)
        pl = PiecewiseLinear(self._xp(v, window), self._points[:, 1:5])
        k, d = pl.segment(v.reshape(-1))
        rgb = np.stack([pl.channel(k, d, c) for c in range(3)], axis=-1)
        alpha = pl.channel(k, d, 3)
        return rgb.reshape(v.shape + (3,)), alpha.reshape(v.shape)

    def classify(self, vol: Volume, window=...) -> Volume:
        """Pre-classify a volume into emission and opacity ``(q_R, q_G, q_B, alpha)``.

        Scalar volume: ``alpha = opacity(v) / opacity_unit`` (per world unit: :meth:`extinction`),
        ``q = rgb(v) · alpha``.  RGB or
        RGBA volume (photographic stacks): the colour is the voxel's own RGB
        scaled to [0, 1] (divided by 255 when the colour exceeds 1, by 65535 when
        it exceeds 255; an alpha by its own range, so a 0 .. 1 mask stays one); the opacity is this function's
        opacity of the luminance ``0.299 R + 0.587 G + 0.114 B`` on that [0, 1] scale, times
        A for RGBA (straight alpha, as image files store it; the ``photo`` preset: A alone).  A 4-channel volume is
        always read as RGBA: an already classified array cannot be told apart (an image file's can:
        :attr:`Volume.photo`), so do not classify twice.

        Changing the transfer function means a new classification and a new
        wavelet transform (pre-classification, paper §2.2).

        A chunked volume (docs/chunked.md) gives a chunked result, each chunk
        classified when it is read, bit for bit as in memory; an "auto" window
        and the RGB scale first take one pass over the volume.  A scalar volume with a value ``subtracted`` is
        classified by this function shifted by it (:meth:`shifted`).

        Parameters
        ----------
        vol : Volume
            1, 3 or 4 channels.
        window : optional
            Overrides this function's window: None (point values are data
            values), "auto" (percentiles of this volume, of its luminance for
            RGB) or (lo, hi), in the input's units as the function's own.

        Returns
        -------
        Volume
            4 channels, float32, same spacing and origin.

        Raises
        ------
        NothingVisibleError
            (an InputError) where no voxel gets any opacity, most often a
            window in other units than the volume's (a HU preset on a volume
            of attenuation): every model and image of it would be blank.  Not
            checked for a chunked volume, classified only as it is read.
        """
        if not isinstance(vol, Volume):
            raise InputError(f"classify needs a clwave.Volume, got {type(vol).__name__}; "
                             "wrap arrays with clwave.Volume(array, spacing=...)")
        tf = self._on(vol, window)
        window, scale = tf._statistics(vol)
        if vol.channels > 1 and window is not None and window[1] - window[0] > 2:
            _warn_colour_window(window)
        paint = tf.painter(vol.channels, window, scale, vol.spacing)
        if vol.chunked:  # each chunk classified when it is read: the values classify gives in memory
            data = vol.data if vol.data.ndim == 4 else vol.data[..., None]
            rgba = data.map_blocks(classified, paint, False, chunks=data.chunks[:3] + ((4,),), dtype=np.float32)
        else:
            rgba = classified(vol.data, paint, True)
            if not rgba[..., 3].any():
                raise tf._nothing_visible(vol, window, scale)
            tf._warn_opaque(vol, window, scale, rgba[..., 3])
        return Volume(rgba, spacing=vol.spacing, origin=vol.origin, obliquity=vol.obliquity, labels=vol.labels,
                      unit=vol.unit, provenance=vol.provenance, modality=vol.modality)

    def _nothing_visible(self, vol, window, scale) -> NothingVisibleError:
        """The refusal of this function (in ``vol``'s data units: :meth:`_on`) without opacity anywhere, naming its span
        and the values it met (a colour volume's luminance), a scalar's in the input's units; its ``cli`` names
        ``--tf-window`` (docs/known-gaps.md §15).  Where the function alone gives some voxel opacity, the colour key
        took it all: the refusal names the key instead."""
        name = f" {self.name}" if self.name else ""
        if self._key is not None and classified(vol.data, self.under(key=None).painter(
                vol.channels, window, scale, vol.spacing), False)[..., 3].any():  # the key took all the opacity
            r, g, b, tolerance = self._key
            tolerance = DEFAULT_TOLERANCE * float(scale[0]) if tolerance is None else tolerance
            line = (f"the colour key ({r:g}, {g:g}, {b:g}), tolerance {tolerance:g}, makes transparent every voxel "
                    f"to which the transfer function{name} gives opacity")
            return NothingVisibleError(f"{line}: give a smaller tolerance, key=(r, g, b, tolerance), or another colour",
                                       cli=f"{line}: give a smaller TOL (--key R,G,B,TOL) or another colour")
        shift = vol.subtracted if vol.channels == 1 else 0.0
        lo, hi = self.data_points(window)[[0, -1]] + shift
        data = vol.data.reshape(-1, vol.channels)
        if vol.channels == 1:
            what, values, units = "values", data[:, 0] + shift, "the input's units"
        else:
            what, values = "luminance (0 .. 1)", _luminance(data[:, :3].astype(np.float64) / scale[:3])
            units = "its luminance, 0 .. 1 whatever the sample type"
        line = (f"the transfer function{name} gives no voxel of this volume any opacity: its points span "
                f"{lo:.4g} .. {hi:.4g} and the volume's {what} lie within {np.nanmin(values):.4g} .. "
                f"{np.nanmax(values):.4g}; give a window in {units}")
        return NothingVisibleError(f"{line} (window=(lo, hi)) or another function",
                                   cli=f"{line} (--tf-window LO,HI) or another preset")

    def _warn_opaque(self, vol, window, scale, alpha=None):
        """Warn where this function (in ``vol``'s data units: :meth:`_on`) is a CT preset on a scalar volume that is no
        CT in Hounsfield units (:func:`~.tf_checks.not_hounsfield`); where it makes the in-memory ``vol`` nearly opaque
        (:meth:`opaque_line` of a strided subsample of its voxels and of its box's faces' voxels), or nearly
        transparent: no ray along the box's axes of optical depth :data:`TRANSPARENT_RAY` (through ``alpha``, the
        classification's opacity, where given; else through a strided grid of the voxels); naming the window in the
        input's units and the data's range (a colour volume's luminance)."""
        faces = [np.moveaxis(vol.data, a, 0)[i].reshape(-1, vol.channels) for a in range(3) for i in (0, -1)]
        data = vol.data.reshape(-1, vol.channels)
        data = data[::max(1, -(-len(data) // AUTO_SAMPLES))]
        values = data[:, 0] if vol.channels == 1 else _luminance(data[:, :3].astype(np.float64) / scale[:3])
        shift = vol.subtracted if vol.channels == 1 else 0.0
        paint = self.painter(vol.channels, window, scale, vol.spacing)
        seen = ("volume's values" if vol.channels == 1 else "volume's luminance", np.nanmin(values) + shift,
                np.nanmax(values) + shift)
        line = vol.channels == 1 and not_hounsfield(self.name, self.data_points(window)[0] + shift, seen[1],
                                                    vol.modality)
        if line:
            warn_outside(ClwaveWarning(line + ": TransferFunction.preset('mri') or 'grey', or window= in its units)",
                                       cli=line + ": --tf mri or --tf grey, or --tf-window LO,HI in its units)"))
        line = self.opaque_line(paint, data, np.concatenate(faces), vol.spacing, vol.shape, window, shift, "volume",
                                seen)
        if line is not None:
            warn_outside(NearlyOpaqueWarning(line + " (window=, opacity_unit=)",
                                             cli=line + " (--tf-window LO,HI or auto, --opacity-unit LENGTH)"))
            return
        step = 1 if alpha is not None else max(1, round((vol.data.size / vol.channels / AUTO_SAMPLES) ** (1 / 3)))
        if alpha is None:
            alpha = classified(vol.data[::step, ::step, ::step], paint, False)[..., 3]
        ray = max(float(alpha.sum(axis=a).max()) * vol.spacing[a] * step for a in range(3))
        if ray < TRANSPARENT_RAY:
            lo, hi = self.data_points(window)[[0, -1]] + shift
            unit = float(min(vol.spacing)) if self._unit is None else self._unit
            line = (f"the transfer function{f' {self.name}' if self.name else ''} makes this volume nearly transparent "
                    f"(no ray along the box's axes has an optical depth above {ray:.3g}: a faint or black picture); "
                    f"its window is {lo:.4g} .. {hi:.4g}, the {seen[0]} {seen[1]:.4g} .. {seen[2]:.4g}: give a window "
                    f"in the input's units or auto, or a shorter opacity unit (now {unit:g})")
            warn_outside(ClwaveWarning(line + " (window=, opacity_unit=)",
                                       cli=line + " (--tf-window LO,HI or auto, --opacity-unit LENGTH)"))

    def opaque_line(self, paint, data, faces, spacing, shape, window, shift, thing, values) -> str | None:
        """Why this function (its points under ``window``, plus ``shift``: the input's units) makes a ``thing``
        ("volume", "model") of ``spacing`` and ``shape`` nearly opaque, in a line naming ``values`` (whose values,
        least, largest, in the input's units) and the fixes; None where it does not.  ``paint`` classifies values as
        :meth:`painter`'s; nearly opaque: the median of ``data`` (a sample of its values at voxel centres) has an
        optical depth across one voxel of at least :data:`OPAQUE_VOXEL` (an opacity unit far below the voxel), or the
        median of ``faces`` (its box's faces' values) across the box's thinnest side :data:`OPAQUE_BOX` (the box drawn
        as a solid: a window far off the data, 0 .. 1 on 16-bit values)."""
        depth = []
        for sample in (data, faces):
            alpha = np.empty((len(sample), 4), np.float32)
            paint(sample, alpha)
            depth.append(float(np.median(alpha[:, 3])))
        voxel, face = depth[0] * min(spacing), depth[1] * min(np.multiply(shape, spacing))
        if voxel < OPAQUE_VOXEL and face < OPAQUE_BOX:
            return None
        lo, hi = self.data_points(window)[[0, -1]] + shift
        where = (f"half its voxels have an optical depth of {voxel:.3g} or more across one voxel"
                 if voxel >= OPAQUE_VOXEL else f"half its faces' voxels have an optical depth of {face:.3g} or more "
                                               f"across the box's thinnest side: a solid box")
        unit = float(min(spacing)) if self._unit is None else self._unit
        what, least, largest = values
        return (f"the transfer function{f' {self.name}' if self.name else ''} makes this {thing} nearly opaque "
                f"({where}); its window is {lo:.4g} .. {hi:.4g}, the {what} {least:.4g} .. {largest:.4g}: "
                f"give a window in the input's units or auto, or a longer opacity unit (now {unit:g})")

    def check_visible(self, vol: Volume):
        """Raise :class:`NothingVisibleError` where this function gives no value of the scalar in-memory ``vol`` any
        opacity, as :meth:`classify` would find, without classifying it: the opacity is linear between the points,
        so it is 0 over the volume's values exactly where it is 0 at their least and largest and at every point
        between (a scalar kept for classifying while rendering, ``classify="post"``); and warn where it makes ``vol``
        nearly opaque everywhere, as :meth:`classify` warns."""
        tf = self._on(vol, ...)
        window, scale = tf._statistics(vol)
        lo, hi = float(np.nanmin(vol.data)), float(np.nanmax(vol.data))
        at = tf.data_points(window)
        if not np.any(tf(np.concatenate([[lo, hi], at[(at > lo) & (at < hi)]]), window)[1]):
            raise tf._nothing_visible(vol, window, scale)
        tf._warn_opaque(vol, window, scale)

    def resolved(self, vol: Volume, window=...) -> "TransferFunction":
        """This function with the window :meth:`classify` would use on ``vol`` made concrete.

        Use it to record exactly how a volume was classified (e.g. in a saved
        file): an "auto" window becomes the (lo, hi) found in ``vol``, in the input's units as every window, an
        opacity unit of one voxel ``vol``'s smallest spacing, and a key "auto" the colour of ``vol``'s box edges.
        """
        if not isinstance(vol, Volume):
            raise InputError(f"resolved needs a clwave.Volume, got {type(vol).__name__}")
        tf = self.under(window)._keyed(vol)
        window = tf._statistics(vol)[0]
        if tf.window == "auto" and vol.channels == 1:  # the percentiles of the stored values
            window = tuple(w + vol.subtracted for w in window)
        return tf.under(window, float(min(vol.spacing)) if self._unit is None else self._unit)

    def _statistics(self, vol):
        """(window, the range of each channel: :func:`rgb_scale`) that :meth:`classify` uses on ``vol``: an "auto"
        window needs the strided subsample, RGB(A) each channel's minimum and maximum, found in one pass over a chunked
        volume."""
        c = _channels(vol)
        win = self._window
        sample, lo, hi = scan(vol.data, win == "auto", c > 1)
        scale = np.ones(1) if c == 1 else rgb_scale(lo, hi)
        if win == "auto":
            win = auto_window(sample if c == 1 else _luminance(sample[:, :3].astype(np.float64) / scale[:3]))
        return win, scale

    def painter(self, channels, window, scale, spacing):
        """``paint(values, out)``: the classification ``out`` (n, 4) float32 of voxels ``values`` (n, channels) of a
        volume of ``spacing``, for whole and chunked volumes alike."""
        extinction = self.extinction(spacing)[:, None]
        if channels == 1:
            pl = PiecewiseLinear(self.data_points(window), np.hstack([self._points[:, 1:4], extinction]))

            def paint(values, out):
                k, d = pl.segment(values[:, 0].astype(np.float64))
                a = pl.channel(k, d, 3)
                out[:, 3] = a
                done = {}
                for ch in range(3):          # q = rgb * alpha; equal colour columns share work
                    key = pl.key(ch)
                    if key not in done:
                        done[key] = pl.channel(k, d, ch)
                    out[:, ch] = done[key] * a
        else:
            pl = PiecewiseLinear(self.data_points(window), extinction)
            key, colour_scale, alpha_scale = self._key, float(scale[0]), float(scale[-1])

            def paint(values, out):
                rgb = values[:, :3].astype(np.float64)
                rgb /= colour_scale
                a = pl.channel(*pl.segment(_luminance(rgb)), 0)
                if channels == 4:
                    a *= values[:, 3].astype(np.float64) / alpha_scale
                if key is not None:
                    a *= key_weight(rgb, key, colour_scale)
                out[:, 3] = a
                rgb *= a[:, None]
                out[:, :3] = rgb
        return paint

    def _xp(self, values, window):
        win = self._window if window is ... else check_window(window)
        if win == "auto":
            win = auto_window(values)
        return self.data_points(win)

    # ----------------------------------------------------------------- serialisation
    def to_dict(self) -> dict:
        """JSON-safe description; ``from_dict(to_dict())`` rebuilds it exactly."""
        win = self._window
        return {
            "format": _FORMAT,
            "version": 2,
            "name": self.name,
            "window": list(win) if isinstance(win, tuple) else win,
            "opacity_unit": self._unit,
            "key": list(self._key) if isinstance(self._key, tuple) else self._key,
            "points": self._points.tolist(),
        }

    @classmethod
    def from_dict(cls, d) -> "TransferFunction":
        """Inverse of :meth:`to_dict` (also accepts a dict with just ``points``, its ``opacity_unit`` None unless
        given).  Version 1 (clwave before the opacity unit, its opacities per world unit) reads with opacity_unit 1, so
        a file's stored function classifies as it did."""
        if not isinstance(d, dict) or "points" not in d:
            raise InputError("transfer function description must be a dict with 'points' "
                             "(rows value, r, g, b, opacity), as written by to_dict()")
        version = d.get("version", 2)
        if d.get("format", _FORMAT) != _FORMAT or version not in (1, 2):
            raise InputError(f"unsupported transfer function format {d.get('format')!r} "
                             f"version {version!r}; expected {_FORMAT!r} version 1 or 2")
        unit = 1.0 if version == 1 else d.get("opacity_unit")
        return cls(d["points"], window=d.get("window"), name=d.get("name"), opacity_unit=unit, key=d.get("key"))

    def __eq__(self, other):
        if not isinstance(other, TransferFunction):
            return NotImplemented
        return (self.name == other.name and self._window == other._window and self._unit == other._unit
                and self._key == other._key and np.array_equal(self._points, other._points))

    __hash__ = None

    def __repr__(self):
        label = f"{self.name!r}, " if self.name else ""
        return (f"TransferFunction({label}{len(self._points)} points, "
                f"window={self._window!r}, opacity_unit={self._unit!r}{f', key={self._key!r}' if self._key else ''})")


# --------------------------------------------------------------------------- helpers
#: Half the width of a categorical function's steps (:meth:`TransferFunction.labels`): a Haar model's values are its
#: labels to float32's rounding, far inside.
LABEL_EDGE = 0.01


def _whole(label) -> bool:
    try:
        return float(label).is_integer()
    except (TypeError, ValueError, OverflowError):
        return False


def _channels(vol) -> int:
    c = vol.channels
    if c not in (1, 3, 4):
        raise InputError(f"cannot classify a {c}-channel volume; give a scalar (1), "
                         "RGB (3) or RGBA (4) volume")
    return c


def _warn_colour_window(window):
    """A colour volume's window wider than twice its luminance's 0 .. 1 (sample units, 0 .. 255 say): nearly
    transparent, or nothing but the window's first values (a new user's 0 .. 100 on an 8-bit stack drew 0.2 % of
    the image's range)."""
    lo, hi = window
    line = (f"a colour volume is classified on its luminance, 0 .. 1 whatever its sample type, so a window of "
            f"{lo:g} .. {hi:g} puts all of it in {1 / (hi - lo):.1%} of the window; give one within 0 .. 1")
    warn_outside(ClwaveWarning(line + " (window=(lo, hi))", cli=line + " (--tf-window LO,HI)"))


def _luminance(rgb):
    return rgb[:, 0] * LUMA[0] + rgb[:, 1] * LUMA[1] + rgb[:, 2] * LUMA[2]
