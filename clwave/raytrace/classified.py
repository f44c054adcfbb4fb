"""Post-classification: a scalar model ray traced through a transfer function given at render time
(docs/raytracing.md §10).

The tracer's set-up holds the scalar's range per block of fine cells (:class:`ScalarRange`, from the brick
pool: the B-splines are non-negative and sum to 1, so the scalar lies between the least and the largest
coefficient reaching a block).  A transfer function then costs its table for the kernel
(``cl/raytrace/classify.h``) and two small kernels (``cl/raytrace/scalar.cl``): per block the largest opacity
over the block's range, the bound that empty-space skipping and early termination use (§4), and its
superblock maxima.  Nothing is expanded, compiled or transformed again.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np
import pyopencl.array as cla
from pyopencl import cltypes
from scipy.special import comb

from ..device import programs
from ..device.constants import BRICK, SUPER
from ..device.kernels import BUFFER, Kernel, in_row_bands
from ..errors import ClwaveWarning, InputError, NearlyOpaqueWarning, warn_outside
from ..io.progress import progress
from ..model.tf_passes import auto_window
from ..model.transfer import TransferFunction
from ..model.transform import sampling_kernel
from ..threads import checkpoint

_RANGE = Kernel("scalar_range", ("out", BUFFER), ("first_slot", np.int32), ("origin", cltypes.int4), ("coef", BUFFER),
                ("bricks", BUFFER), ("frames", BUFFER), ("boxes", BUFFER), ("order", np.int32))
_BOUNDS = Kernel("classified_bounds", ("bound", BUFFER), ("range", BUFFER), ("tf", BUFFER), ("slack", np.float32),
                 ("n", np.int32))
_SUPER = Kernel("superblock_max", ("out", BUFFER), ("ns", cltypes.int4), ("bound", BUFFER), ("nb", cltypes.int4))
GROUP = 256  #: work-group of classified_bounds
#: at how many voxel centres of the pool's field a window "auto" looks
AUTO_VALUES = 1 << 16
#: at how many voxel centres of a model's box's faces the nearly-opaque check evaluates it (ScalarRange.opaque)
FACE_VALUES = 1 << 10
#: a tracer keeps the ranges per block of this many details (each picks its own bricks, docs/raytracing.md §8)
RANGES_KEPT = 8
#: a block's range is widened by this much of the scalar's largest magnitude (the kernels' float32 rounding)
RANGE_SLACK = 1e-6
#: a scalar changing by less than this share of the transfer function's span per unit length is flat: unlit
FLAT = 1e-4
#: the scalar pool's coefficients are s = offset + step q, q a base per tile plus 0..Q_BITS - 2 or Q_BITS bits, an
#: offset per slot and a step per slot: the widest full-detail slot's range / Q_MAX, and the widest coarser one's for
#: the slots only coarser details read (docs/raytracing.md §10)
Q_BITS = 16
Q_MAX = 2 ** Q_BITS - 1
#: per slot of a packed pool: its (offset, step), where its tiles' entries lie and how many tiles along y (``Quant`` in
#: ``cl/raytrace/scalar_pool.h``)
QUANT = np.dtype([("offset", "<f4"), ("step", "<f4"), ("word", "<u4"), ("tiles_y", "<u4")])
#: a packed pool's tile: TILE x TILE of a slot's x rows (in y and z), its q with its own base and bits (the unit the
#: counts in docs/known-gaps.md §10 found to pay; a cell's rows each lie in one tile)
TILE = 4
#: spare words at the end of a packed pool (a row reads eight bytes)
POOL_PAD = 4
#: coefficients packed at a time (float64 work arrays of this many elements)
Q_CHUNK = 1 << 20


def tf_table(tf: TransferFunction, window, spacing) -> np.ndarray:
    """The kernel's table of ``tf`` under ``window`` (data units) on a model of ``spacing`` (its opacities as extinction
    per world unit, :meth:`~clwave.TransferFunction.extinction`), (rows, 4) float64 (``cl/raytrace/tf_table.h``).

    u = s scale + shift maps the first point to 0 and the last to 1 (values of order 1 in any data units);
    row 0 is (scale, shift, K, 0), rows 1..K the points' (u, opacity, max tree node, 0), then per interval k = 0..K
    three rows: (u_ref, alpha_ref, alpha_slope, 0), (rgb_ref, 0), (rgb_slope, 0); outside the points the end rows hold.
    """
    values = tf.data_points(window)
    scale = 1.0 / (values[-1] - values[0])
    u = (values - values[0]) * scale
    K, rows = len(u), np.column_stack([tf.points[:, 1:4], tf.extinction(spacing)])  # r, g, b, extinction
    table = np.zeros((1 + K + 3 * (K + 1), 4))
    table[0, :3] = scale, -values[0] * scale, K
    table[1:K + 1, :2] = np.column_stack([u, rows[:, 3]])
    tree = np.concatenate([np.zeros(K), rows[:, 3]])  # nodes 1..K-1 the larger of their two children, leaves K..2K-1
    hi = K
    while hi > 1:  # nodes [lo, hi) from their children, all at hi or above
        lo = (hi + 1) // 2
        tree[lo:hi] = np.maximum(tree[2 * lo:2 * hi:2], tree[2 * lo + 1:2 * hi:2])
        hi = lo
    table[1:K, 2] = tree[1:K]
    k = np.arange(K + 1)
    first, du = np.clip(k - 1, 0, K - 1), np.zeros(K + 1)  # each interval's first point, and its width in u
    du[1:K] = np.diff(u)
    slope = np.zeros((K + 1, 4))
    np.divide(rows[np.minimum(k, K - 1)] - rows[first], du[:, None], out=slope, where=du[:, None] > 0)
    at = 1 + K + 3 * k
    table[at, :3] = np.column_stack([u[first], rows[first, 3], slope[:, 3]])
    table[at + 1, :3] = rows[first, :3]
    table[at + 2, :3] = slope[:, :3]
    return table


def clamped(tf: TransferFunction, value_range) -> TransferFunction:
    """``tf`` (points in data units) applied to the field clamped to ``value_range`` (lo, hi), the input's range in
    the same units: TF∘clamp is again piecewise linear, constant beyond its ends, so its points inside (lo, hi) stay,
    those outside give way to its values at lo and hi (docs/raytracing.md §10), its opacity unit kept.  A function
    whose points all lie within the range is returned as it is (the same table, bit for bit); ``value_range`` None:
    ``tf``."""
    values = tf.data_points()
    if value_range is None or (values[0] >= value_range[0] and values[-1] <= value_range[1]):
        return tf
    lo, hi = value_range
    at = np.unique(np.clip(values, lo, hi))  # the points inside, and lo or hi where some lie beyond
    if len(at) < 2:  # all on one side, or a constant input: one value's classification everywhere
        at = np.array([lo, hi if hi > lo else lo + max(1.0, abs(lo))])
    rows = tf.points[:, 1:5]
    points = np.column_stack([at] + [np.interp(np.minimum(at, hi), values, rows[:, c]) for c in range(4)])
    return TransferFunction(points, name=tf.name, opacity_unit=tf.opacity_unit)


#: the opacity a pixel needs to show: 13 of the 255 levels of an 8-bit picture from the background
#: (:meth:`ScalarRange.faint`)
SHOWS = 0.05
#: an image fewer of whose pixels show (:data:`SHOWS`) is nearly empty: 1 in 100 pixels, a few specks
NEARLY_EMPTY = 0.01


@dataclass
class Classification:
    """One transfer function's kernel arguments: the table and the classified bounds."""

    tf: TransferFunction    # as given, in the input's units
    window: tuple | None    # its window in the input's units ("auto" resolved)
    table: cla.Array        # (rows, 4) real
    bound: cla.Array        # per block: the largest opacity
    super_bound: cla.Array  # per superblock
    super_origin: np.ndarray
    box: tuple              # clip box (x, y, z): the data's box (data_box) where the function sees anything
    grad_floor: float       # world gradients of the scalar this short are flat
    seconds: float          # what the change of transfer function cost
    range: cla.Array        # the detail's range per block that the bounds come from
    opacity: float          # the largest opacity it gives any block: 0, nothing to see
    shows_zero: bool        # it gives the field's 0 (where no brick lies) an opacity: the box is the data's


class ScalarRange:
    """The scalar's range per block of every brick slot of a ray tracer's pool (set up once, on the device), laid
    out per detail when a render first asks for it (:mod:`clwave.raytrace.lod`: each detail picks its slots), and
    the classifications of transfer functions from it (:meth:`classify`: a table, two small kernels).

    Made, the pool on the device (expanded one float a coefficient: :func:`~.bricks.build`'s ``scalar``) is packed
    with 0 to 16 bits a coefficient, a width and base per tile, an offset and a step per slot (:func:`pack`: the
    full-detail slots packed as without level of detail; ``CLW_SCALAR_POOL`` in ``cl/raytrace/field_bspline.h``); the
    ranges are widened by half each slot's step, so they hold the float model and the one rendered.  ``abandon``:
    the tracer's set-up given up between two bands of slots of the ranges, and two chunks of the packing
    (:func:`pack`).
    """

    def __init__(self, tracer, abandon=None):
        f, cc = tracer.bricks, tracer.cc
        q = cc.queue
        self.cc, self.bricks, self.tracer = cc, f, tracer
        self.noise_floor, self.spacing = tracer.grad_floor("single"), min(tracer.wv.spacing)
        self.subtracted = tracer.wv.subtracted  # the model's values are the input's minus it (Volume.subtracted)
        known = tracer.wv.value_range  # the input's (min, max), on the model's values: the classification's clamp
        self.value_range = None if known is None else tuple(v - self.subtracted for v in known)
        self.kernels = programs.build(cc, ["raytrace/scalar.cl"])
        self.slot_range = None  # bricks in a scratch file: |s| <= the block bound
        self.step = 0.0  # the packed pool's largest step (none in a scratch file: floats)
        self.length = float(np.linalg.norm(np.multiply(f.shape, tracer.wv.spacing))) * BRICK  # the bricks' diagonal
        self.data_box = data_box(tracer.wv.shape, tracer.orders[0])
        self.sample = np.zeros(1, np.float32) if f.resident else None  # no bricks at all: s = 0 everywhere
        if f.resident and len(f.levels):
            tables = tracer.field_tables
            slot_range = cla.empty(q, (len(f.levels), SUPER, SUPER, SUPER, 2), np.float32)
            at = np.zeros((len(f.bricks), 4), np.int32)
            at[:, :3] = (f.bricks - f.origin)[:, ::-1]
            at = cla.to_device(q, at)

            def ranges(size, first):  # in bands of slots, the set-up given up between two
                checkpoint(abandon)
                _RANGE(self.kernels, q, size, (SUPER ** 3, 1), out=slot_range, first_slot=first,
                       origin=f.origin[::-1], coef=tables["coef"], bricks=at, frames=tables["frames"],
                       boxes=tables["boxes"], order=f.orders[0])

            in_row_bands(q, ranges, (SUPER ** 3, len(f.bricks)), (SUPER ** 3, 1))
            scalar = f.pool.get()  # one float a coefficient (bricks.build's scalar)
            full = full_detail_slots(f)
            self.sample = _sample(scalar, f.boxes[:, 0], full if full.any() else ~full, tracer.wv.groups[0].wavelet,
                                  f.levels)
            words, quant = pack(scalar, f.boxes[:, 0], full, abandon)
            self.step = float(np.max(quant["step"]))
            if self.step <= np.finfo(np.float32).tiny:  # the step floored (_step): fewer than Q_BITS of the range
                warn_outside(ClwaveWarning(
                    f"this scalar model's values are so small (their range under {Q_MAX} times float32's least normal "
                    f"number, {np.finfo(np.float32).tiny:.3g}) that its bricks pack them in fewer than {Q_BITS} bits: "
                    f"its shading is coarser than the tolerance; multiply the volume's values (by 1e30, say) before "
                    f"making the model"))
            del scalar
            self.slot_range = slot_range.get()  # the decoded coefficients lie within half their step of the floats
            self.slot_range += (quant["step"][:, None] / 2 * np.array([-1, 1], np.float32))[:, None, None, None, :]
            tracer.replace_pool(cla.to_device(q, words), cla.to_device(q, quant))
            tracer.defines["CLW_SCALAR_POOL"] = None
        self.slack = RANGE_SLACK * float(tracer.q_bound)
        self.ranges = {}  # per detail (its pages' bytes): the range per block on the device
        self.last = None
        self.faces = None  # the model at voxel centres of its box's faces (face_values), when first asked
        self.auto = None  # window "auto" resolved from the sample (window), when first asked

    def range(self, at):
        """The range per block (Z, Y, X, 2) on the device at the detail of ``at`` (a ``FieldAt``): the slots' ranges
        laid out by its pages (absent bricks: s = 0), or +-its block bounds for bricks in a scratch file."""
        key = at.pages.tobytes()
        if key not in self.ranges:
            if len(self.ranges) >= RANGES_KEPT:
                self.ranges.pop(next(iter(self.ranges)))
            if self.slot_range is not None:
                grid = self.bricks.bound_grid(at.pages, self.slot_range)
            else:
                bound = at.block_bound.get()
                grid = np.stack([-bound, bound], axis=-1)
            self.ranges[key] = cla.to_device(self.cc.queue, grid)
        return self.ranges[key]

    def window(self, tf: TransferFunction):
        """``tf``'s window in the input's units; "auto" from the percentiles of the full-detail slots' field values at
        lattice points (docs/raytracing.md §10), the same with level of detail or without, and whatever the order, plus
        the value subtracted from the model's, within the input's range where it is known; resolved once a tracer."""
        if tf.window != "auto":
            return tf.window
        if self.sample is None:
            raise InputError('a transfer function window "auto" at render time needs the bricks on the device; '
                             "give the window (lo, hi) (--tf-window LO,HI)")
        if self.auto is None:  # the sample is the model's, fixed: resolved once, whatever the function
            lo, hi = (w + self.subtracted for w in auto_window(self.sample))
            known = self.tracer.wv.value_range  # the field is classified clamped to it: a window beyond its ends
            if known is not None and max(lo, known[0]) < min(hi, known[1]):  # gave its least value some opacity
                lo, hi = max(lo, known[0]), min(hi, known[1])
            self.auto = (lo, hi)
        return self.auto

    def stored(self, tf: TransferFunction) -> TransferFunction:
        """``tf`` on the model's values, the input's minus the value subtracted (:meth:`TransferFunction.shifted`),
        under :meth:`window`."""
        return tf.under(self.window(tf)).shifted(self.subtracted)

    def invisible(self, post: Classification, image=None) -> str | None:
        """Why ``post`` draws nothing (its transfer function gives no block of the model any opacity: most often a
        window in other units than the model's, HU on a model of attenuation), in a line naming the fix; else None,
        and a warning where ``image`` (premultiplied RGBA, given for a whole image) is nearly empty (:meth:`faint`)."""
        if post.opacity > 0:
            if image is not None:
                self.faint(post, float(np.mean(image[..., 3] >= SHOWS)))
            return None
        name = f"the transfer function{f' {post.tf.name}' if post.tf.name else ''}"
        if not np.any(post.tf.points[:, 4]):
            return f"{name} has opacity 0 at every point: give it some opacity (or another function)"
        lo, hi = post.tf.data_points(post.window)[[0, -1]]
        whose, values = "the input's", self.tracer.wv.value_range  # what the classification sees (clamped)
        if values is None and self.slot_range is not None:
            whose, values = "this model's", (self.slot_range[..., 0].min() + self.subtracted,
                                             self.slot_range[..., 1].max() + self.subtracted)
        held = "" if values is None else f"; {whose} values lie within {values[0]:.4g} .. {values[1]:.4g}"
        return (f"{name} gives no value of this model any opacity (its points span {lo:.4g} .. {hi:.4g}{held}): give "
                f"a window in the input's units (--tf-window LO,HI) or another function")

    def faint(self, post: Classification, shown: float):
        """Warn where the share ``shown`` of the image's pixels that show (:data:`SHOWS`) is below
        :data:`NEARLY_EMPTY`, naming where the transfer function is opaque (:func:`opaque_where`) and the values the
        model's bricks hold (their ranges bound the field).  Where those values do not reach its largest opacity, its
        opacity lies at values the model barely reaches: the window that shows them; else it lies within them and what
        it makes opaque is small or thin: the picture may be right, a shorter opacity unit thickens thin features, and
        a model that smooths its voxels (order 3 and up, not interpolating) is told how it lowers thin peaks.  Once a
        function and window (a viewer's frames, a turntable's views)."""
        key = ("faint", told_key(post.tf), post.window)
        if shown >= NEARLY_EMPTY or key in self.tracer.told:
            return
        self.tracer.told.add(key)
        name = f"the transfer function{f' {post.tf.name}' if post.tf.name else ''}"
        points, opacity = post.tf.data_points(post.window), post.tf.points[:, 4]
        held = [-np.inf, np.inf] if self.tracer.wv.value_range is None else list(self.tracer.wv.value_range)
        if self.slot_range is not None:  # classified clamped to the input's range (docs/raytracing.md §10)
            held = [max(held[0], self.slot_range[..., 0].min() + self.subtracted),
                    min(held[1], self.slot_range[..., 1].max() + self.subtracted)]
        line = (f"the image is nearly empty: {100 * shown:.2g} % of its pixels hide {100 * SHOWS:g} % of the "
                f"background or more ({round(255 * SHOWS)} of 255 levels of an 8-bit picture); {name} is opaque "
                f"{opaque_where(points, opacity)}, and this model's values lie within {held[0]:.4g} .. {held[1]:.4g}")
        inside = np.clip(np.concatenate([held, points]), *held)  # the held values' ends and the points between
        if np.interp(inside, points, opacity).max() < opacity.max():
            warn_outside(ClwaveWarning(line + f": put its opacity there (a preset: window=({held[0]:.4g}, "
                                              f"{held[1]:.4g}))",
                                       cli=line + f": put its opacity there (a preset: --tf-window {held[0]:.4g},"
                                                  f"{held[1]:.4g}; a file: its values)"))
            return
        wv = self.tracer.wv
        unit = float(min(wv.spacing)) if post.tf.opacity_unit is None else post.tf.opacity_unit
        line += (": its opacity lies within them, so what it makes opaque is small or thin in this model (the picture "
                 "may be right)")
        smooths = "" if wv.interpolate or self.tracer.orders[0] < 3 else (
            "; this model smooths its voxels (its value at a voxel centre is a weighted mean of the voxel and its "
            "neighbours), so a layer a voxel or two thick peaks below its voxels' values: {}")
        thin = f"; a shorter {{}} (now {unit:g}) makes thin features more opaque"
        warn_outside(ClwaveWarning(line + smooths.format("a model of interpolate=True passes through them") +
                                   thin.format("opacity_unit"),
                                   cli=line + smooths.format("--interpolate makes the model pass through them") +
                                   thin.format("--opacity-unit")))

    def opaque(self, tf: TransferFunction) -> str | None:
        """Why ``tf`` makes this model nearly opaque (:meth:`TransferFunction.opaque_line`, as a volume's
        classification warns, docs/model.md §5), in a line; else None.  The voxels' sample is the field's at voxel
        centres that an "auto" window reads (:attr:`sample`: the space its full-detail bricks fill; none for bricks in a
        scratch file: the faces alone), the faces' the model evaluated at voxel centres of its box's six faces (at
        most :data:`FACE_VALUES`, once a tracer), both as classified: clamped to the input's range."""
        wv = self.tracer.wv
        if self.faces is None:
            self.faces = face_values(wv)
        stored = self.stored(tf)
        seen = clamped(stored, self.value_range)
        paint = seen.painter(1, seen.window, 1.0, wv.spacing)
        known = wv.value_range
        values = ("input's values", *known) if known is not None else \
            ("model's values on its faces", self.faces.min() + self.subtracted, self.faces.max() + self.subtracted)
        data = self.faces if self.sample is None else self.sample[:, None]
        return stored.opaque_line(paint, data, self.faces, wv.spacing, wv.shape, ..., self.subtracted, "model", values)

    def classify(self, tf, cc, real, at=None) -> Classification:
        """The kernel arguments of ``tf`` at the detail of ``at`` (default full detail), reused while the transfer
        function, detail and precision stay the same (its ``seconds`` then 0: what this render paid)."""
        start = time.perf_counter()  # a detail's first classification lays its ranges out too
        at = self.tracer.field_at(0) if at is None else at
        last, ranges = self.last, self.range(at)
        if last is not None and last.tf == tf and last.table.dtype == real and last.range is ranges:
            return replace(last, seconds=0.0)  # nothing changed: this render pays nothing for it
        window, stored = self.window(tf), clamped(self.stored(tf), self.value_range)
        table, q = tf_table(stored, stored.window, self.tracer.wv.spacing), cc.queue
        bound = cla.empty(q, ranges.shape[:3], np.float32)
        super_bound = cla.empty(q, at.super_bound.shape, np.float32)
        n = bound.size  # explicit work-groups: PoCL's default for this size was a tenth as fast
        _BOUNDS(self.kernels, q, (-(-n // GROUP) * GROUP,), (GROUP,), bound=bound, range=ranges,
                tf=cla.to_device(q, table.astype(np.float32)), slack=self.slack, n=n)
        _SUPER(self.kernels, q, super_bound.shape[::-1], None, out=super_bound, ns=super_bound.shape[::-1],
               bound=bound, nb=bound.shape[::-1])
        # flat: below FLAT of the span per unit length, or the float32 field's rounding noise, in both precisions
        values = stored.data_points()
        floor = max(self.noise_floor, FLAT * (values[-1] - values[0]) / self.spacing)
        lo, hi = self.data_box  # where the field is 0 (no brick) the function sees 0: visible only if it shows 0
        shows_zero = bool(stored(np.zeros(1))[1][0])
        if not shows_zero:
            lo, hi = np.maximum(lo, at.box[0]), np.minimum(hi, at.box[1])
        self.last = Classification(tf, window, cla.to_device(q, table.astype(real)), bound, super_bound,
                                   at.super_origin, (lo, hi), floor, 0.0, ranges,
                                   float(super_bound.get().max(initial=0.0)), shows_zero)
        q.finish()
        self.last.seconds = time.perf_counter() - start
        return self.last


def opaque_where(values, opacity) -> str:
    """Where a transfer function of points at ``values`` (ascending) with ``opacity`` there (linear between, the end
    points' held beyond) gives opacity, in words: its intervals, each "below a", "from a to b" or "above b"."""
    live = opacity > 0
    spans = np.r_[live[0], live[:-1] | live[1:], live[-1]]  # (-inf, v0], each [v_i, v_i+1], [v_last, inf)
    ends = np.r_[-np.inf, values, np.inf]  # span k is ends[k] .. ends[k + 1]
    first = np.flatnonzero(spans & ~np.r_[False, spans[:-1]])
    last = np.flatnonzero(spans & ~np.r_[spans[1:], False])
    words = [("everywhere" if np.isinf(lo) and np.isinf(hi) else f"below {hi:.4g}" if np.isinf(lo) else
              f"above {lo:.4g}" if np.isinf(hi) else f"from {lo:.4g} to {hi:.4g}")
             for lo, hi in zip(ends[first], ends[last + 1])]
    return " and ".join([", ".join(words[:-1]), words[-1]] if len(words) > 1 else words)


def data_box(shape, order) -> tuple:
    """(lo, hi), (x, y, z) grid-0 fine coordinates: the box of the outermost voxel centres of a volume of ``shape``
    (z, y, x) modelled at ``order``, the bounds of VTK's image data, beyond which post-classification sees nothing
    (docs/raytracing.md §10); a Haar model's (the voxels themselves, boxes) and an axis of one voxel keep the
    outermost voxels' whole thickness."""
    n = np.array(shape[::-1], float)
    whole = 0.5 * ((n == 1) | (order == 1))
    return order / 2.0 - whole, n - 1 + order / 2.0 + whole


def face_values(wv) -> np.ndarray:
    """(n, 1): the scalar model ``wv`` at most :data:`FACE_VALUES` voxel centres of its box's six faces, evenly strided
    over each face, in its stored values (``WaveletVolume.evaluate``: the band sum, whatever the model's size)."""
    points = []
    for axis in range(3):  # z, y, x
        rest = [n for a, n in enumerate(wv.shape) if a != axis]
        stride = max(1, math.ceil(math.sqrt(rest[0] * rest[1] * 6 / FACE_VALUES)))
        for end in (0, wv.shape[axis] - 1):
            grid = np.stack(np.meshgrid(np.arange(0, rest[0], stride), np.arange(0, rest[1], stride), indexing="ij"),
                            -1).reshape(-1, 2)
            points.append(np.insert(grid, axis, end, axis=1))
    zyx = np.concatenate(points)  # voxel i of an axis of n at origin + (i - (n - 1) / 2) spacing (coordinates.md §1)
    world = (zyx - (np.array(wv.shape) - 1) / 2) * np.array(wv.spacing)
    return wv.evaluate(world[:, ::-1] + np.array(wv.origin), method="bands")


def full_detail_slots(field) -> np.ndarray:
    """(slots,) bool: the slots of a :class:`~clwave.raytrace.bricks.BrickField` that a full-detail render reads
    (detail 0's pages and their mixed bricks' coarse slots, docs/raytracing.md §3, §8): all of a tracer's slots
    without level of detail, and the same slots, coefficient for coefficient, in one with it."""
    full = np.zeros(len(field.levels), bool)
    full[field.pages[0][field.pages[0] >= 0]] = True
    alt = field.mixes[full, 0]
    full[alt[alt >= 0]] = True
    return full


def _sample(scalar, boxes, slots, wavelet, levels) -> np.ndarray:
    """At most AUTO_VALUES values of the field the slots ``slots`` (bool) pick hold, for window "auto": at the voxel
    centres of the bricks those slots fill (a level-l slot's point stands for 8^l fine cells, and a slot's halo, the
    supports reaching in from its neighbours, is left out: coarse bricks count as much as the space they fill), each
    from the coefficients around it by the model's sampling kernel per axis (``sampling_kernel``, docs/model.md §1).
    The field's values, not its coefficients, whose spread grows with the order (a quintic's exceed the data by far):
    about the same window whatever the wavelet, and wherever the pool holds those slots (docs/raytracing.md §10)."""
    taps = sampling_kernel(wavelet)
    w = len(taps)
    box = boxes[slots].astype(np.int64)
    lv = np.asarray(levels, np.int64)[slots]
    cell = 8.0 ** lv  # fine cells a point of each slot stands for
    # the points of each slot's own brick: windows inside the slot, at most the brick's cells a side
    side = np.maximum(np.minimum(box[:, :3] - w + 1, (BRICK >> lv)[:, None]), 1)
    skip = (box[:, :3] - w + 1 - side) // 2  # the halo before them
    points = np.prod(side, axis=1)
    space = np.cumsum(points * cell)
    if not len(space) or not space[-1]:
        return np.zeros(1, np.float32)
    n = min(AUTO_VALUES, int(points.sum()))
    at = (np.arange(n) + 0.5) * (space[-1] / n)  # evenly over the space the bricks fill
    k = np.searchsorted(space, at, side="right")
    box, side, skip = box[k], side[k], skip[k]
    i = np.floor((at - space[k]) / cell[k]).astype(np.int64) + points[k]  # its point in the brick
    corner = [np.clip(skip[:, 0] + i % side[:, 0], 0, None),  # its window's first coefficient in the slot (x, y, z)
              np.clip(skip[:, 1] + i // side[:, 0] % side[:, 1], 0, None),
              np.clip(skip[:, 2] + i // (side[:, 0] * side[:, 1]), 0, None)]
    last = box[:, 3] + np.prod(box[:, :3], axis=1) - 1  # a slot narrower than the window: its last coefficient
    values = np.zeros(n)                                 # repeats
    for dz in range(w):
        for dy in range(w):
            row = box[:, 3] + ((corner[2] + dz) * box[:, 1] + corner[1] + dy) * box[:, 0] + corner[0]
            weight = taps[dz] * taps[dy]
            for dx in range(w):
                values += weight * taps[dx] * scalar[np.minimum(row + dx, last)]
    return values.astype(np.float32)


def pack(scalar, boxes, full=None, abandon=None) -> tuple:
    """(words, quant): the pool's coefficients ``scalar`` (float32; slot s a box ``boxes[s]`` = (nx, ny, nz, first) of
    coefficients, x fastest) packed for ``cl/raytrace/scalar_pool.h`` (docs/raytracing.md §10).  A step S for the
    slots a full-detail render reads (``full``, (slots,) bool; default every slot) and one for the others (a tracer's
    coarser details), each the widest range of its slots / Q_MAX rounded up in float32, so the full-detail slots are
    packed alike whatever coarser details the pool holds; per slot its offset, its least coefficient (float32, so
    exact), and per coefficient q the nearest whole number of steps above it (float64), so ``offset + S q`` is within
    S / 2 of each coefficient.  Each tile (TILE x TILE of a slot's x rows in y and z) holds its q - base in the fewest
    bits b (0..14, 16) covering its q, base its least q.  Slot s's words from ``quant["word"][s]``: per tile (z, y
    order) its entry (its first word, base | b << 16), then the tiles' words, each tile's rows (z, y order) one after
    another from a whole word; then POOL_PAD spare words.  ``quant`` is (slots,) QUANT.  Given up between two chunks
    (``abandon``, :func:`~clwave.threads.checkpoint`)."""
    boxes = np.asarray(boxes, np.int64).reshape(-1, 4)
    sizes = np.prod(boxes[:, :3], axis=1)
    quant = np.zeros(max(len(boxes), 1), QUANT)
    if not sizes.sum():
        return np.zeros(POOL_PAD, np.uint32), quant
    starts, end = boxes[:, 3], int(boxes[-1, 3] + sizes[-1])  # the slots lie one after another
    lo = np.minimum.reduceat(scalar[:end], starts)
    span = np.maximum.reduceat(scalar[:end], starts).astype(np.float64) - lo
    full = np.ones(len(boxes), bool) if full is None else np.asarray(full, bool)
    for part in (full, ~full):
        if part.any():
            quant["step"][part] = _step(span[part].max())
    inverse = np.divide(1.0, quant["step"].astype(np.float64), out=np.zeros(len(quant)), where=quant["step"] > 0)
    quant["offset"] = lo
    out, at, chunks = [], 0, []
    for shape in np.unique(boxes[:, :3], axis=0):  # the slots of one box shape, about Q_CHUNK coefficients at a time
        slots = np.flatnonzero(np.all(boxes[:, :3] == shape, axis=1))
        per = max(Q_CHUNK // int(np.prod(shape)), 1)
        chunks += [(shape, slots[k:k + per]) for k in range(0, len(slots), per)]
    for shape, chunk in progress(chunks, desc="scalar pool"):
        checkpoint(abandon)
        words, start = _pack_slots(scalar, shape, starts[chunk], lo[chunk].astype(np.float64), inverse[chunk], at)
        quant["word"][chunk], quant["tiles_y"][chunk] = start, -(-shape[1] // TILE)
        out.append(words)
        at += len(words)
    return np.concatenate(out + [np.zeros(POOL_PAD, np.uint32)]), quant


def _step(span) -> np.float32:
    """The step of slots whose widest range is ``span``: span / Q_MAX rounded up in float32, at least float32's least
    normal number (a subnormal step is 0 in the kernels' fast arithmetic: a scalar of about 1e-36 rendered empty; its
    q then stay below Q_MAX)."""
    step = np.float32(max(span / Q_MAX, np.finfo(np.float32).tiny))
    return np.nextafter(step, np.float32(np.inf)) if float(step) * Q_MAX < span else step


def _pack_slots(scalar, shape, firsts, offsets, inverse, at) -> tuple:
    """(words, start): the words of slots of one box ``shape`` (nx, ny, nz) whose coefficients start at ``firsts``
    (``inverse``: 1 / each slot's step), for :func:`pack`, laid out one after another from the pool's word ``at``, and
    where each slot's start."""
    nx, ny, nz = (int(v) for v in shape)
    m, ty, tz = len(firsts), -(-ny // TILE), -(-nz // TILE)
    coef = scalar[firsts[:, None] + np.arange(nx * ny * nz)].astype(np.float64)
    q = np.rint((coef - offsets[:, None]) * inverse[:, None]).astype(np.int32).reshape(m, nz, ny, nx)
    tiled = np.pad(q, ((0, 0), (0, tz * TILE - nz), (0, ty * TILE - ny), (0, 0)), mode="edge").reshape(
        m, tz, TILE, ty, TILE, nx).transpose(0, 1, 3, 2, 4, 5).reshape(m, tz, ty, TILE * TILE * nx)
    base = tiled.min(axis=3)
    bits = np.searchsorted(2 ** np.arange(Q_BITS + 1) - 1, tiled.max(axis=3) - base)
    bits[bits == Q_BITS - 1] = Q_BITS  # four fields in eight bytes from any byte (cl/raytrace/scalar_pool.h)
    # a tile's rows (z, y) inside the slot, one after another, each row's x: a coefficient's place in its tile
    rows = (np.arange(tz * TILE) < nz).reshape(tz, 1, TILE, 1) & (np.arange(ty * TILE) < ny).reshape(1, ty, 1, TILE)
    rows = rows.reshape(tz, ty, TILE * TILE)
    place = ((np.cumsum(rows, axis=-1) - 1)[..., None] * nx + np.arange(nx)).reshape(tz, ty, -1)
    counts = np.broadcast_to(rows.sum(axis=-1) * nx, (m, tz, ty))
    data = -(-counts * bits // 32).reshape(m, -1)
    start = np.concatenate([[0], np.cumsum(2 * ty * tz + data.sum(axis=1))])
    tile_word = start[:-1, None] + 2 * ty * tz + np.cumsum(data, axis=1) - data  # after the slot's entries
    words = np.zeros(int(start[-1]), np.uint32)
    entry = (start[:-1, None] + 2 * np.arange(ty * tz)).ravel()
    words[entry] = at + tile_word.ravel()
    words[entry + 1] = base.ravel().astype(np.uint32) | bits.ravel().astype(np.uint32) << np.uint32(16)
    # field i of a tile from word w at bit 32 w + i b, in word order: fields never overlap, so a word's 64-bit window
    # is the OR of those that start in it (each below 2^48; a 0-bit tile's fields, all 0, may start past the end)
    keep = np.broadcast_to(rows[None, ..., None], (m, tz, ty, TILE * TILE, nx)).reshape(m, tz, ty, -1)
    bit = (tile_word.reshape(m, tz, ty, 1) * 32 + place * bits[..., None].astype(np.int64))[keep]
    value = (tiled - base[..., None])[keep].astype(np.uint64) << (bit & 31).astype(np.uint64)
    key = bit >> 5
    first = np.flatnonzero(np.concatenate([[True], key[1:] != key[:-1]]))
    key, window = key[first], np.bitwise_or.reduceat(value, first)
    inside = key < len(words)
    words[key[inside]] |= (window[inside] & 0xFFFFFFFF).astype(np.uint32)
    inside &= key + 1 < len(words)
    words[key[inside] + 1] |= (window[inside] >> np.uint64(32)).astype(np.uint32)
    return words, at + start[:-1]


def post_nodes(nodes, n_samples) -> np.ndarray:
    """``nodes`` (:func:`clwave.raytrace.quadrature.sample_tables`) with what ``cl/raytrace/classify.h`` adds: the
    matrices from the samples, and from the gradient's lanes 0..8, to their Bernstein coefficients."""
    return np.concatenate([nodes, bernstein_matrix(nodes[:n_samples]).ravel(), bernstein_matrix(nodes[:9]).ravel()])


def bernstein_matrix(xi) -> np.ndarray:
    """(n, n) the matrix from a polynomial's values at the n points ``xi`` in [-1, 1] to its Bernstein
    coefficients of degree n - 1 on [-1, 1] (``cl/raytrace/classify.h``)."""
    n = len(xi) - 1
    t = (np.asarray(xi, float) + 1) / 2
    k = np.arange(n + 1)
    basis = comb(n, k) * t[:, None] ** k * (1 - t[:, None]) ** (n - k)  # (points, k)
    return np.linalg.inv(basis)


def check_post(tracer, tf, absorption):
    """Refuse what a transfer function at render time (a TransferFunction, :func:`as_transfer_function` made it)
    cannot take: it needs a scalar model, the B-spline field and absorption."""
    if tracer.wv.channels != 1:
        raise InputError(f"transfer_function= classifies a scalar model while rendering; this one has "
                         f"{tracer.wv.channels} channels (already classified: render it without one)")
    if tf.key is not None:  # a scalar's colour is the function's: no key to take out
        raise InputError("a transfer function with a colour key classifies a colour volume before the transform; a "
                         "scalar model is classified while rendering without one: leave the key out")
    if tracer.scalar is None:
        raise InputError("transfer_function= needs field='bspline' (--field bspline)")
    if not absorption:
        raise InputError("transfer_function= is for emission-absorption images; X-ray mode (absorption=False) "
                         "integrates the scalar itself")


def told_key(tf: TransferFunction) -> tuple:
    """``tf`` as a key of what a tracer has told, as ``==`` compares it (its points as bytes: their JSON took 3.7 s a
    render at 10⁶ points, docs/benchmarks.md §26)."""
    return tf.name, tf.window, tf.opacity_unit, tf.key, tf.points.tobytes()


def warn_opaque(scalar: ScalarRange, tf: TransferFunction, told: set):
    """Warn where ``tf`` makes the model of ``scalar`` nearly opaque (:meth:`ScalarRange.opaque`), once per function
    in ``told`` (a tracer's)."""
    key = ("opaque", told_key(tf))
    if key in told:
        return
    told.add(key)
    line = scalar.opaque(tf)
    if line is not None:
        warn_outside(NearlyOpaqueWarning(line + " (transfer_function=TransferFunction(..., window=, opacity_unit=))",
                                         cli=line + " (--tf-window LO,HI or auto, --opacity-unit LENGTH)"))
