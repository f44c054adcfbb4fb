"""Ray tracing in wavelet space (paper §3, docs/raytracing.md): shaded emission-absorption
images, or line integrals, within an absolute error bound per pixel.

:class:`RayTracer` prepares a model's field with one of two backends (``"bspline"``: bricks of
B-spline coefficients, each at its own lattice level, :mod:`clwave.raytrace.bricks`; ``"wavelet"``:
per-ray active lists, the paper's reference, of the model without the B-spline field's content clamp,
docs/raytracing.md §4) and its bounds for empty-space skipping;
``cl/raytrace/raytrace.cl`` marches, in passes over regions of bricks where they do not fit the device.
"""

from __future__ import annotations

import time

import numpy as np
import pyopencl.array as cla
from pyopencl import cltypes

from ..device import programs
from ..device.constants import BLOCK, SUPER
from ..device.kernels import BUFFER, REAL, Kernel, row_bands, zeros
from ..model.geometry import world_to_fine_affine
from ..model.camera import Camera, View
from ..model.clip import Clip, check_clip
from ..model.conebeam import ConeBeam, check_camera, resolve_view, view_record
from ..model.signs import warn_both_signs
from ..device.context import ComputeContext
from ..errors import InputError, finite_number, flag
from ..device.memory import TRACED_PIXEL_BYTES, check_image, device_budget, parse_cap
from .bounds import warn_below_tolerance, warn_empty, warn_packed
from .bricks import ABSENT, BRICK, build, group_defines, plan
from .wavelet_field import WaveletField
from .passes import carried, planned
from .lod import Detail, FieldAt, brick_caps, field_at, pick
from .classified import QUANT, ScalarRange, check_post, post_nodes, warn_opaque
from .progressive import frames
from .quadrature import sample_tables
from .shading import Phong, light_directions
from ..io.result import RenderResult
from ..model.tf_file import as_transfer_function
from ..model.transfer import TransferFunction
from ..model.wavelet import WaveletVolume, check_model
from ..io.progress import progress
from ..threads import drain, one_at_a_time


FIELDS = ("bspline", "wavelet")
#: what a tracer holds of its field at the default detail, the bounds and tables a render reads through its
#: ``at`` (:meth:`RayTracer._detail`): the finest FieldAt's (B-spline field), or the WaveletField's
AT_DEFAULT = ("box", "block_bound", "q_bound", "occupied_fraction", "field_tables", "super_bound", "super_bound_host",
              "super_origin")
B, I32, INT4, FLOAT4 = BUFFER, np.int32, cltypes.int4, cltypes.float4
#: the arguments of each field backend (FIELD_PARAMS of cl/raytrace/field_*.h)
FIELD_ARGS = dict(bspline=(("coef", B), ("pages", B), ("page_origin", INT4), ("page_shape", INT4), ("frames", B),
                           ("boxes", B), ("lattices", B), ("mixes", B), ("pieces", B), ("quant", B),
                           ("joins", B)),
                  wavelet=(("coef", B), ("info", B), ("shape", B), ("band_lo", B), ("poly", B), ("trace", B)))


def _checked_tolerance(tolerance) -> float:
    """The tolerance of a render, checked (InputError naming the argument)."""
    tol = finite_number(tolerance, "tolerance")
    if tol <= 0:
        raise InputError(f"tolerance={tolerance!r} must be a positive absolute error")
    return tol


def raytrace_kernel(field: str) -> Kernel:
    """The arguments of ``raytrace`` (cl/raytrace/raytrace.cl) with a field backend."""
    return Kernel("raytrace", ("image", B), ("stats", B), ("lattice_stats", B), ("width", I32), ("height", I32),
                  ("first_row", I32), *FIELD_ARGS[field],
                  ("bound", B), ("occ_origin", INT4), ("occ_shape", INT4), ("super_bound", B),
                  ("super_origin", INT4), ("super_shape", INT4), ("content", B), ("content_origin", INT4),
                  ("content_shape", INT4), ("coarse_bound", REAL), ("box_lo", FLOAT4),
                  ("box_hi", FLOAT4), ("clip", B), ("nclip", I32), ("base", FLOAT4), ("du", FLOAT4), ("dv", FLOAT4),
                  ("dir", FLOAT4),
                  ("perspective", I32), ("to_fine_scale", FLOAT4), ("to_fine_offset", FLOAT4), ("nodes", B),
                  ("weights", B), ("tol", REAL), ("shade_gain", REAL), ("grad_floor", REAL), ("lights", B),
                  ("nlights", I32), ("phong", FLOAT4), ("tf", B), ("passes", I32), ("pass_lo", FLOAT4),
                  ("pass_hi", FLOAT4), ("carry", B), ("ledger", B), ("resume", B))


GRAD_NOISE = 16  # alpha gradients below this many rounding units of the field bound per spacing: unlit
SIMPSON_DEPTH = 16  # adaptive Simpson halves a segment at most this often (flagged when it must stop)
ACTIVE = 1024    # entries of a ray's active list (wavelet field); more fall back to visiting every index
DETAILS_KEPT = 8   # a tracer keeps the bounds of this many details (docs/raytracing.md §8)
#: single-precision builds may reassociate sums and flush denormals (2-3 % of a render, results moved within the
#: arithmetic's rounding); float64 references are built as written
FAST_MATH = ("-cl-unsafe-math-optimizations", "-cl-denorms-are-zero")


class RayTracer:
    """A wavelet volume prepared for ray tracing on one device; render many views with it, from several threads at
    once if need be (renders on a device take their turn, docs/coordinates.md §4).

    ``field`` chooses how the field is evaluated: ``"bspline"`` (bricks, fast) or ``"wavelet"`` (active lists over
    the kept coefficients, the paper's reference, unclamped: docs/raytracing.md §4); see the module
    docstring.  ``active`` bounds the wavelet field's per-ray list. ``device_memory`` caps the device memory it uses
    (bytes, or a size such as ``"2GiB"``); a B-spline field bigger than that (or than the device) goes to a scratch
    file and renders in passes (docs/raytracing.md §6). ``region`` (first, stop): only the bricks of those layers
    along array axis 0 (z), and rays marched inside them only: one worker's part of an image rendered on a Dask
    cluster (:mod:`clwave.raytrace.regions`). ``lod=True`` (B-spline field) also expands the bricks of every coarser
    detail, so that ``render(..., detail=)`` picks one without a new set-up (docs/raytracing.md §8); it costs the
    coarser pools' memory and their share of the set-up.  ``lod`` may also name the detail levels to expand (e.g.
    ``(3,)``: the coarsest of 3 levels alone), the finest of them the default detail of a render.  :meth:`open` sets
    up from a ``.clw`` file in stages, the coarsest detail first (docs/raytracing.md §8).  ``content_clamp=False``
    renders the whole model, its ringing beyond the source's non-zero voxels included, where the default clamps it
    to them (docs/raytracing.md §4): the line integrals splatting computes, for X-ray images that match it.
    ``abandon`` (a ``threading.Event``): once another thread sets it, the set-up stops at its next checkpoint (a
    slab of the expansion, a brick row of the plan, a band of a scalar model's ranges) with
    :class:`~clwave.threads.Abandoned`, whatever the model (docs/raytracing.md §8).
    """

    def __init__(self, wv: WaveletVolume, device=None, field="bspline", active=ACTIVE, device_memory=None,
                 region=None, lod=False, content_clamp=True, abandon=None):
        check_model(wv, "ray tracing")
        if not isinstance(content_clamp, bool):
            raise InputError(f"content_clamp={content_clamp!r} must be True (the model within its content) or False")
        if abandon is not None and not callable(getattr(abandon, "is_set", None)):
            raise InputError(f"abandon={abandon!r} must be a threading.Event (set to give the set-up up) or None")
        if not content_clamp and wv.content_mask is not None:
            wv = wv.unmasked()
        check_field(field)
        if wv.channels > 4:
            raise InputError(f"ray tracing takes at most 4 channels, the volume has {wv.channels}")
        if int(active) != active or active < 1:
            raise InputError(f"active={active!r} must be a positive whole number of list entries")
        if region is not None and (field != "bspline" or len(np.shape(region)) != 1 or len(region) != 2
                                   or not all(isinstance(v, (int, np.integer)) for v in region)
                                   or not region[0] < region[1]):
            raise InputError(f"region={region!r} must be (first, stop) brick layers along z with first < stop, "
                             f"for the B-spline field")
        self.details = _details(lod, wv.levels, field)  # the detail levels expanded (docs/raytracing.md §8)
        self.wv, self.field, self.active, self.region = wv, field, int(active), region
        self.lod = self.details != (0,)
        self.expansions, self._at = 0, {}  # B-spline expansions so far; FieldAt per detail asked for
        self.told = set()  # warnings given, each once a tracer (bounds.warn_below_tolerance); a viewer clears it a view
        self.cc = ComputeContext.get(device)
        self.lock = self.cc.lock  # one render at a time on the device (threads.one_at_a_time)
        self.budget = device_budget(self.cc, device_memory)
        self.orders = [g.wavelet.order for g in wv.groups]
        self.alpha_group = next((i for i, g in enumerate(wv.groups) if 3 in g.channels), -1)
        if field == "bspline":
            self._expand(abandon)
        else:
            self._wavelet(abandon)
        # a scalar model: its range per block, for transfer functions at render time (docs/raytracing.md §10)
        self.scalar = ScalarRange(self, abandon) if wv.channels == 1 and field == "bspline" else None

    def _expand(self, abandon):
        """B-spline field: the bricks (:mod:`clwave.raytrace.bricks`), and their per-block maxima as bounds."""
        p = plan(self.wv, self.details, abandon)
        if self.region is not None:  # the bricks of the region's layers only
            layers = p.origin[0] + np.arange(p.level.shape[1])
            p.level[:, (layers < self.region[0]) | (layers >= self.region[1])] = ABSENT
        self.bricks = build(self.wv, self.cc, self.budget, p, scalar=self.wv.channels == 1,  # ScalarRange packs it
                            abandon=abandon)
        self.expansions += 1
        self.setup_seconds = self.bricks.seconds
        self.occ_origin = self.bricks.origin * SUPER
        full = self.field_at(self.details[0])  # the finest; other details pick other slots (docs/raytracing.md §8)
        for name in AT_DEFAULT:
            setattr(self, name, getattr(full, name))
        self.content_origin, self.content_cells = self.occ_origin * BLOCK, None  # the bricks clamp to content
        self.content = cla.to_device(self.cc.queue, np.ones(1, np.uint8))
        self.content_shape = np.zeros(3, np.int64)
        # explicit groups: PoCL's default for a big image (up to 4096 rays) keeps every ray's private
        # arrays at once, which overflowed its threads' stacks
        self.local_size = (8, 8)
        self.defines = group_defines(self.orders)
        self.quant = zeros(self.cc.queue, 1, QUANT)  # a packed scalar pool's Quant per slot (classified.pack)

    def _wavelet(self, abandon):
        """Wavelet field: the dense bands' tables, bounds, content cells and build options
        (:mod:`clwave.raytrace.wavelet_field`), held as the B-spline field's are (:meth:`_expand`)."""
        w = WaveletField(self.wv, self.cc, self.budget, self.active, self.orders, abandon)
        for name in AT_DEFAULT:
            setattr(self, name, getattr(w, name))
        self.setup_seconds, self.occ_origin, self.poly = w.setup_seconds, w.occ_origin, w.poly
        self.content, self.content_origin, self.content_cells, self.content_shape = (
            w.content, w.content_origin, w.content_cells, w.content_shape)
        self.defines, self.local_size = w.defines, w.local_size

    def field_at(self, caps) -> FieldAt:
        """The B-spline field at detail ``caps`` (one level, or one per brick): made once per detail from the
        bricks already expanded (docs/raytracing.md §8), the last few kept."""
        key = np.asarray(caps, np.int8).tobytes() + bytes([np.ndim(caps)])
        if key not in self._at:
            if len(self._at) >= DETAILS_KEPT:
                self._at.pop(next(iter(self._at)))
            self._at[key] = field_at(self.bricks, self.cc, pick(self.bricks, caps))
        return self._at[key]

    def replace_pool(self, pool, quant=None):
        """The bricks' pool on the device replaced by ``pool`` (post-classification's scalar pool, docs/raytracing.md
        §10; ``quant``: its QUANT per slot): the field's tables of every detail name the new one."""
        self.bricks.pool = pool
        self.quant = self.quant if quant is None else quant
        self._at.clear()
        self.field_tables = self.field_at(0).field_tables

    def _detail(self, detail, view, scale, offset) -> tuple:
        """(FieldAt, the meta's detail level: an int, or the least and largest over the bricks) of a render."""
        detail = Detail(self.details[0]) if detail is None else Detail.of(detail, self.wv.levels)
        every = len(self.details) == self.wv.levels + 1
        if detail.level not in self.details or (detail.pixels is not None and not every):
            raise InputError("detail= needs a tracer of the B-spline field that holds every detail "
                             "(RayTracer(wv, lod=True))" if not self.lod else
                             f"this tracer holds details {', '.join(map(str, self.details))} only, not detail "
                             f"{detail.level}" + ("" if detail.pixels is None else
                                                   " with a screen-space error (that needs lod=True)"))
        if self.field != "bspline":
            return self, 0
        if detail.pixels is None:
            return self.field_at(detail.level), detail.level
        f = self.bricks
        lo = (BRICK * (np.indices(f.shape).reshape(3, -1).T + f.origin))[:, ::-1] - offset  # (x, y, z) fine
        caps = brick_caps(detail, self.wv.levels, view, (lo / scale, BRICK / scale), self.wv.spacing)
        if np.ndim(caps):
            caps = caps.reshape(f.shape)
            return self.field_at(caps), [int(caps.min()), int(caps.max())]
        return self.field_at(caps), caps

    def coarse_bound(self, tol) -> float:
        """Superblocks bounded by at most this are one region for skipping (``cl/raytrace/raytrace.cl``): what
        the field could add along any chord through one is then at most tol / 4096."""
        return tol / 4096 / (BLOCK * SUPER * np.sqrt(3) * max(self.wv.spacing))

    def grad_floor(self, precision="single", q_bound=None) -> float:
        """World gradients of alpha at most this long count as flat when shading (``cl/raytrace/raytrace.cl``):
        on a plateau of alpha the summed gradient is rounding noise of this size (``q_bound``: the field's
        largest block bound, by default at full detail)."""
        eps = np.finfo(np.float64 if precision == "double" else np.float32).eps
        return GRAD_NOISE * eps * (self.q_bound if q_bound is None else q_bound) / min(self.wv.spacing)

    @one_at_a_time
    def render(self, camera: Camera | ConeBeam | View, tolerance=1e-3, lights=None, shading=True, absorption=True,
               precision="single", trace=0, detail=None, transfer_function=None, clip=None) -> RenderResult:
        """One image; see :func:`raytrace` for the parameters (``camera`` may also be its
        :class:`~clwave.model.camera.View` of this model, resolved already).

        ``detail`` (B-spline field): a level from 0 (full detail, the default) to ``levels``, or a
        :class:`~clwave.raytrace.lod.Detail` (a level cap and/or a screen-space error in pixels); the bricks of
        every detail are expanded when the tracer is made, so changing it rebuilds nothing (docs/raytracing.md §8).

        ``trace`` (wavelet field, tests): record each ray's active set on its first ``trace``
        segments in ``meta["active_trace"]`` (see ``cl/raytrace/field_wavelet.h``).
        """
        return drain(self.rendering(camera, tolerance, lights, shading, absorption, precision, trace, detail,
                                    transfer_function, clip))

    def rendering(self, camera, tolerance=1e-3, lights=None, shading=True, absorption=True, precision="single",
                  trace=0, detail=None, transfer_function=None, clip=None):
        """:meth:`render` as a generator yielding between its bands of rows, returning its result (a viewer's saved
        image takes turns with the tabs' frames there, docs/viewer.md §5; the caller holds :attr:`lock` for each
        stage): a ray is one work-item's whatever the bands, and what the bands read is the render's own (its image,
        classification and detail's tables: another render between two stages makes others), so the image is
        :meth:`render`'s bit for bit.  Bricks in a scratch file, traced in passes through one pool, are one stage."""
        wv, cc = self.wv, self.cc
        tol = _checked_tolerance(tolerance)
        absorption = flag(absorption, "absorption")
        if not absorption:
            warn_both_signs(wv)
        clip, transfer_function = check_clip(clip), as_transfer_function(transfer_function)
        if transfer_function is None and absorption and wv.channels == 1 and wv.transfer_function is not None:
            transfer_function = TransferFunction.from_dict(wv.transfer_function)  # the model's default
        if transfer_function is not None:
            check_post(self, transfer_function, absorption)
        elif absorption and wv.photo:
            raise InputError("emission-absorption ray tracing needs a classified model; this one holds a photo's "
                             "colour and alpha (an RGBA image file): classify the volume first, e.g. "
                             "TransferFunction.preset('photo').classify(volume) (opacity its alpha, colour its RGB), "
                             "or pass absorption=False for line integrals")
        elif absorption and wv.channels != 4:
            raise InputError(f"emission-absorption ray tracing needs an RGBA volume (4 channels), this one has "
                             f"{wv.channels}; classify it first (TransferFunction.classify), give a scalar one a "
                             f"transfer_function= to classify it while rendering, or pass absorption=False for "
                             f"line integrals")
        if precision not in ("single", "double"):
            raise InputError(f"precision={precision!r} must be 'single' or 'double'")
        if precision == "double" and not cc.queue.device.double_fp_config:
            raise InputError(f"{cc.info.name} has no float64 support; use precision='single'")
        view = resolve_view(camera, wv)
        H, W = view.size
        check_image(cc, (H, W), H * W * TRACED_PIXEL_BYTES, "render a smaller image (at most {n}x{n} here)",
                    self.budget)
        light_dirs = light_directions(lights, view.n)
        phong, shading_note = self._phong(shading, absorption, lights)

        nodes, weights = sample_tables(3 * (max(self.orders) - 1))
        n_samples = len(weights)
        real = np.float64 if precision == "double" else np.float32
        if transfer_function is not None:  # docs/raytracing.md §10
            nodes = post_nodes(nodes, n_samples)
        defines = dict(self.defines, CLW_ALPHA=self.alpha_group if transfer_function is None else 0,
                       CLW_SAMPLES=n_samples, CLW_MAX_DEPTH=SIMPSON_DEPTH,
                       CLW_LATTICE="0.5" if len({o % 2 for o in self.orders}) > 1 else "1.0")
        if min(self.orders) >= 3:  # the field and its gradient are continuous across knot planes
            defines["CLW_JOIN"] = None
        if not absorption:
            defines["CLW_XRAY"] = None
        elif phong is not None:
            defines["CLW_SHADE"] = None
        if transfer_function is not None:
            defines["CLW_POST"] = None
        if self.content_shape.any():
            defines["CLW_CONTENT"] = None
        if precision == "double":
            defines["CLW_DOUBLE"] = None
        if trace and self.field == "wavelet":
            defines["CLW_TRACE"] = int(trace)
        start = time.perf_counter()
        kernels = programs.build(cc, ["raytrace/raytrace.cl"], defines, () if precision == "double" else FAST_MATH)
        compile_seconds = time.perf_counter() - start

        q = cc.queue
        nodes, weights = cla.to_device(q, nodes.astype(real)), cla.to_device(q, weights.astype(real))
        scale, offset = world_to_fine_affine(self.orders[0], wv.shape, wv.spacing, wv.origin)
        if view.perspective:  # the ray of pixel (c, r) leaves the eye along -n + s_u u + s_v v (View.slopes)
            base, du, dv, direction = view.eye, view.slope[0] * view.u, view.slope[1] * view.v, -view.n
            if any(view.principal):  # a cone beam's principal point off the detector's centre
                direction = direction + view.principal[0] * view.u + view.principal[1] * view.v
        else:
            base, du, dv, direction = view.target, view.pixel * view.u, view.pixel * view.v, -view.n
        start = time.perf_counter()
        at, detail_level = self._detail(detail, view, scale, offset)
        detail_seconds = time.perf_counter() - start
        # the transfer function's table and bounds at this detail (docs/raytracing.md §10)
        post = None if transfer_function is None else self.scalar.classify(transfer_function, cc, real, at)
        if post is not None:
            warn_opaque(self.scalar, transfer_function, self.told)
        light_buf = np.zeros((max(1, len(light_dirs)), 4), np.float32)
        if light_dirs:
            light_buf[: len(light_dirs), :3] = light_dirs
        p = phong or Phong()
        shade_gain = (p.ambient + (p.diffuse + p.specular) * len(light_dirs)) if phong else 1.0
        warn_below_tolerance(wv, (post.opacity if post else at.q_bound) * shade_gain, tol, self.told)
        if not absorption and self.scalar is not None:
            warn_packed(self.scalar.step, self.scalar.length, tol, self.told)
        per_pixel = H * W * (48 + 9 * np.dtype(real).itemsize)  # image, two stats; carry, ledger, resume
        passes = planned(self, view, scale, offset, per_pixel, at, post is not None and post.shows_zero)
        image = cla.empty(q, (H, W, 4), np.float32) if passes is None else zeros(q, (H, W, 4), np.float32)
        stats = cla.empty(q, (H, W, 4), np.int32) if passes is None else zeros(q, (H, W, 4), np.int32)
        lattice_stats = cla.empty(q, (H, W, 4), np.int32) if passes is None else zeros(q, (H, W, 4), np.int32)
        carry, ledger, resume = carried(q, (H, W), real, tol, absorption, passes is not None)
        traced = None
        if self.field == "wavelet":
            traced = zeros(q, (H, W, max(1, int(trace)), 4), np.int32)
            field_tables = dict(self.field_tables, poly=cla.to_device(q, self.poly.astype(real)), trace=traced)
        skip = dict(bound=at.block_bound, super_bound=at.super_bound, super_origin=at.super_origin[::-1],
                    super_shape=at.super_bound.shape[::-1], box_lo=at.box[0], box_hi=at.box[1])
        if post is not None:  # the classified opacity bounds the field (docs/raytracing.md §10)
            skip.update(bound=post.bound, super_bound=post.super_bound, super_origin=post.super_origin[::-1],
                        super_shape=post.super_bound.shape[::-1], box_lo=post.box[0], box_hi=post.box[1])
        skip.update(_clipped(clip, skip["box_lo"], skip["box_hi"], scale, offset, q, self.region is None, wv.origin))
        start = time.perf_counter()
        rounded = tuple(-(-n // m) * m for n, m in zip((W, H), self.local_size))  # whole work-groups
        arguments = dict(
            image=image, stats=stats, lattice_stats=lattice_stats, width=W, height=H, **skip,
            occ_origin=self.occ_origin[::-1], occ_shape=at.block_bound.shape[::-1], content=self.content,
            content_origin=self.content_origin[::-1], content_shape=self.content_shape[::-1],
            coarse_bound=self.coarse_bound(tol), du=du, dv=dv, dir=direction, perspective=view.perspective,
            base=base - wv.origin, to_fine_offset=offset + scale * wv.origin,  # about the centre: coordinates.md §1
            to_fine_scale=scale, nodes=nodes, weights=weights, tol=tol, shade_gain=shade_gain,
            grad_floor=post.grad_floor if post else self.grad_floor(precision, at.q_bound),
            lights=cla.to_device(q, light_buf), nlights=len(light_dirs),
            phong=[p.ambient, p.diffuse, p.specular, p.shininess], carry=carry, ledger=ledger, resume=resume,
            tf=post.table if post is not None else carry)
        if self.field == "bspline":
            arguments["quant"] = self.quant
        several = passes is not None and len(passes) > 1  # a bar over the scratch file's regions
        for slots, lo, hi in progress(passes or [(None, np.zeros(3), np.zeros(3))], desc="ray-tracing passes",
                                      enabled=None if several else False):
            if self.field == "bspline":
                field_tables = None  # the last region's pool goes before the next one comes
                field_tables = at.field_tables if slots is None else dict(self.bricks.tables(cc, None, slots),
                                                                              joins=at.joins)
            stages = row_bands(q, lambda size, first: raytrace_kernel(self.field)(
                kernels, q, size, self.local_size, field_tables, real_type=real, first_row=first,
                passes=passes is not None, pass_lo=lo, pass_hi=hi, **arguments),
                rounded, self.local_size)  # bounded launches: Ctrl-C within a fraction of a second
            if passes is None:
                yield from stages
            else:  # the next pass's bricks go into the pool this one's read
                drain(stages)
        seconds = time.perf_counter() - start
        img = image.get()
        counts = stats.get().reshape(-1, 4).astype(np.int64)
        img = img if absorption else img[..., : wv.channels]
        whole = None if self.region or clip is not None or not counts[:, 0].any() else img  # not a part, clip, miss
        nothing_visible = None if post is None else self.scalar.invisible(post, whole)
        if self.region is None and not nothing_visible:  # a cluster's part may miss; an invisible function is said
            warn_empty(int(counts[:, 0].sum()), self.told)  # where it is found
        meta = dict(
            method="raytrace", mode="emission-absorption" if absorption else "xray", field=self.field,
            device=cc.describe(), coefficients=wv.kept, tolerance=tol, precision=precision,
            shading=shading_note, lights=[np.round(d, 6).tolist() for d in light_dirs] if phong else [],
            segments=int(counts[:, 0].sum()), samples_per_segment=n_samples,
            segments_shaded_at_midpoint=int(counts[:, 1].sum()),
            integrand_evaluations=int(counts[:, 2].sum()),
            rays_terminated_early=int(np.count_nonzero(counts[:, 3] & 1)),
            rays_at_simpson_depth_limit=int(np.count_nonzero(counts[:, 3] & 2)),
            rays_active_list_overflowed=int(np.count_nonzero(counts[:, 3] & 4)),
            occupied_blocks=round(at.occupied_fraction, 4), detail=detail_level, detail_seconds=detail_seconds,
            setup_seconds=self.setup_seconds, compile_seconds=compile_seconds, render_seconds=seconds,
            segments_per_second=float(counts[:, 0].sum() / seconds) if seconds > 0 else 0.0,
            passes=1 if passes is None else len(passes), device_budget=self.budget.total,
            segments_by_lattice=dict(zip(("1", "2", "4", "8+"),
                                         lattice_stats.get().reshape(-1, 4).sum(axis=0).tolist())))
        meta.update(view_record(camera, view, wv.unit))
        if post is not None:
            meta.update(classification="post", transfer_function=post.tf.to_dict(),
                        tf_window=None if post.window is None else list(post.window),
                        classify_seconds=post.seconds, nothing_visible=nothing_visible)
        if self.field == "bspline":
            meta.update(bricks=len(at.slots), brick_levels=np.bincount(self.bricks.levels[at.slots]).tolist(),
                        brick_slots=len(self.bricks.levels), brick_pool_bytes=self.bricks.pool_bytes,
                        mixed_bricks=int(np.sum(self.bricks.mixes[at.slots, 0] >= 0)),  # docs/raytracing.md §3
                        pool="device" if self.bricks.resident else "scratch file")
        if trace and self.field == "wavelet":
            meta["active_trace"] = traced.get()
        return RenderResult(img, meta)

    @classmethod
    def open(cls, path, device=None, device_memory=None, lod=False):
        """A :class:`~clwave.raytrace.staged.StagedTracer` of a ``.clw`` file: the coarsest detail from the file's
        approximation alone, ready on return; the whole file's tracer (``lod`` as here) set up in a background
        thread; its ``refine(camera)`` yields frames from the first to the full-detail image
        (docs/raytracing.md §8)."""
        from .staged import StagedTracer

        return StagedTracer(cls, path, device=device, device_memory=device_memory, lod=lod)

    def refine(self, camera: Camera | ConeBeam, tolerance=1e-3, lights=None, shading=True, absorption=True, *,
               steps=None, budget=None, error=None, transfer_function=None, clip=None):
        """Frames of ``camera`` from cheap to exact (:mod:`clwave.raytrace.progressive`, docs/raytracing.md §9),
        for a viewer that shows each as it comes: a generator (``RaytraceFrame`` s: ``image``, ``figures()``),
        the last bit for bit :meth:`render` at full detail; stop iterating when the view changes (nothing is
        left running); any tracer refines (the frames are its own renders of reduced images).  Use it from one
        thread at a time.  ``transfer_function``, ``clip``: as :meth:`render`'s, the same at every frame."""
        options = dict(tolerance=tolerance, lights=lights, shading=shading, absorption=absorption,
                       transfer_function=as_transfer_function(transfer_function), clip=check_clip(clip))
        return frames(self, camera, options, steps, budget, error)

    def _phong(self, shading, absorption, lights):
        """(Phong or None, what the meta says about shading); ``lights`` given to an image without shading, which
        they would not change, refused."""
        if not absorption or shading is False or shading is None:
            if lights:
                unlit, given = ("an X-ray", "absorption=False") if not absorption else ("an unshaded image",
                                                                                      "shading=False")
                raise InputError(f"lights={lights!r} light a shaded image; {unlit} ({given}) has none, so they change "
                                 f"nothing: leave them out", cli=f"--light lights a shaded image; {unlit} has none, "
                                 f"so it changes nothing: leave it out")
            return None, "off: X-ray mode" if not absorption else "off"
        phong = shading if isinstance(shading, Phong) else Phong() if shading is True else None
        if phong is None:
            raise InputError("shading must be True, False or a clwave.Phong(...)")
        if self.orders[self.alpha_group] == 1:
            return None, "off: the Haar basis has no usable gradient, rendered unshaded"
        return phong, "phong"


def _clipped(clip, lo, hi, scale, offset, queue, whole, shift) -> dict:
    """The kernel's ``box_lo``, ``box_hi``, ``clip`` and ``nclip`` (docs/raytracing.md §12): the support box ``lo`` ..
    ``hi`` (grid-0 fine (x, y, z)) cut by the clip's box, and its half-spaces in the kernel's world (less ``shift``);
    a clip keeping nothing of that box refused where it is the ``whole`` model's (a cluster's slab may miss it)."""
    if clip is None:
        return dict(box_lo=lo, box_hi=hi, clip=cla.zeros(queue, (1, 4), np.float32), nclip=0)
    if whole and not clip.keeps((lo - offset) / scale, (hi - offset) / scale):
        world = [np.round((b - offset) / scale, 6).tolist() for b in (lo, hi)]
        raise InputError(f"{clip.describe()} keeps nothing of the volume's content, which lies within {world[0]} .. "
                         f"{world[1]} (world x, y, z): move or turn it to cut through the volume")
    with np.errstate(over="ignore"):  # a face beyond float32's range (1e300) is as far: what is kept is unchanged
        if clip.lo is not None:
            lo, hi = (np.maximum(lo, np.array(clip.lo) * scale + offset),
                      np.minimum(hi, np.array(clip.hi) * scale + offset))
        rows, top = clip.half_spaces(), np.finfo(np.float32).max
        rows = np.clip(rows + np.outer(rows[:, :3] @ np.array(shift), [0, 0, 0, 1]), -top, top).astype(np.float32)
    return dict(box_lo=lo, box_hi=hi, clip=cla.to_device(queue, rows), nclip=len(rows))


def _details(lod, levels, field) -> tuple:
    """The detail levels a tracer expands: ``lod`` False (full detail), True (every one) or the levels named."""
    if lod is True or lod is False:
        details = tuple(range(levels + 1)) if lod else (0,)
    elif np.ndim(lod) == 1 and len(lod) and all(isinstance(v, (int, np.integer)) and 0 <= v <= levels for v in lod):
        details = tuple(sorted({int(v) for v in lod}))
    else:
        raise InputError(f"lod={lod!r} must be True, False or detail levels from 0 to {levels}")
    if details != (0,) and field != "bspline":
        raise InputError("level of detail (lod=) needs the B-spline field")
    return details


def raytrace(wv: WaveletVolume, camera: Camera | ConeBeam, tolerance=1e-3, lights=None, shading=True, absorption=True,
             device=None, *, field="bspline", precision="single", device_memory=None, scheduler=None,
             tracer: RayTracer | None = None, transfer_function=None, clip: Clip | None = None) -> RenderResult:
    """Ray trace a wavelet volume (paper §3).

    Parameters
    ----------
    wv : WaveletVolume
        Four channels ``(q_R, q_G, q_B, alpha)`` (``TransferFunction.classify``) for
        emission-absorption, or one (a scalar) with ``transfer_function``; any channels for ``absorption=False``.
    camera : Camera or ConeBeam
        Orthographic or perspective; an eye inside the volume integrates from the eye.  A :class:`ConeBeam`
        traces its own detector's rays (principal point and pixel spacings included): a DRR with ``absorption=False``.
    tolerance : float
        Absolute error allowed on each output value, early ray termination included.
    lights : list of (azimuth, elevation), optional
        Directional lights in degrees (world frame, like the camera); default one headlight
        from the camera's direction; ``[]`` leaves the ambient term only.
    shading : bool or Phong
        Phong shading with normals from the analytic gradient of alpha.
    absorption : bool
        ``False`` returns the line integral of every channel (X-ray mode), as splatting does.
    field : "bspline" or "wavelet"
        Evaluate the field from fine B-spline grids expanded on the device (fast), or sum
        the kept wavelet coefficients along each ray with active lists (paper §3.3, the
        reference); both give the same image within the tolerance where the model has no content mask.
        With one, only the B-spline field zeroes the fine coefficients of empty voxels: the wavelet
        field is the unclamped model, whose rim ringing differs from it by up to 0.29 on a
        thresholded model (docs/raytracing.md §4).
    precision : "single" or "double"
        Kernel arithmetic; "double" gives converged references (float64 devices only).
    device_memory : int or str, optional
        Device memory to use at most (bytes, or e.g. ``"2GiB"``); bricks beyond it render in passes
        (docs/raytracing.md §6).
    scheduler : optional
        Render on a Dask cluster (:mod:`clwave.schedulers`: a number of local worker processes, an address or a
        ``distributed.Client``): each worker traces the rays through its slab of bricks, opening the model's
        ``.clw`` file itself (docs/raytracing.md §7).
    transfer_function : TransferFunction, optional
        Classify a scalar model while rendering (post-classification, docs/raytracing.md §10): colour and opacity as
        ``TransferFunction.classify`` gives them (docs/model.md §5), normals from the scalar's gradient; another
        function or window needs no new set-up.  Or a preset name, a ``.json``/``.csv`` file, a matplotlib colormap
        (``tf_file.as_transfer_function``).  Default: the model's (``from_volume(transfer_function=)``, its ``.clw``'s).
    clip : Clip, optional
        Keep only what lies inside a crop box and/or half-spaces (world coordinates): each ray's integral is taken
        over its interval inside them, exactly (docs/raytracing.md §12); a new clip rebuilds nothing.
    tracer : RayTracer, optional
        Render with this one; without it, calls on the same model, device and field share one
        (:meth:`WaveletVolume.shared`): the field is set up once.

    Returns a :class:`RenderResult`: premultiplied ``(R, G, B, A)`` with ``A = 1 - T``, or
    the line integrals; ``meta`` holds the field, segment and evaluation counts, shading,
    and timings (B-spline expansion and kernel compile apart).
    """
    check_camera(camera)
    transfer_function = as_transfer_function(transfer_function)
    if scheduler is not None:
        from ..schedulers import client_for
        from .regions import check_cluster_model, raytrace_on_cluster

        check_cluster_model(wv, field)  # before any worker starts
        if transfer_function is not None and getattr(transfer_function, "window", None) == "auto":
            raise InputError('a transfer function window "auto" would be resolved by each worker on its own part; '
                             "give the window (lo, hi) to render on a cluster")
        tol, cap = _checked_tolerance(tolerance), parse_cap(device_memory)
        light_directions(lights, None)  # checked before any worker starts
        options = dict(tolerance=tol, lights=lights, shading=shading, absorption=absorption, precision=precision,
                       transfer_function=transfer_function, clip=check_clip(clip))
        with client_for(scheduler) as client:  # which checks the scheduler before starting anything
            return raytrace_on_cluster(RayTracer, wv, camera, client, options, device, cap)
    if tracer is None:
        check_model(wv, "ray tracing")
        tracer = shared_tracer(wv, device, field, device_memory)
    return tracer.render(camera, tolerance=tolerance, lights=lights, shading=shading, absorption=absorption,
                         precision=precision, transfer_function=transfer_function, clip=clip)


def check_field(field):
    """``field`` one of :data:`FIELDS`, checked before a one-shot call's tracer is looked up by it."""
    if not isinstance(field, str) or field not in FIELDS:
        raise InputError(f"ray tracing field must be one of {', '.join(FIELDS)}, got {field!r}")


def shared_tracer(wv, device=None, field="bspline", device_memory=None) -> RayTracer:
    """The full-detail tracer of ``wv`` that :func:`raytrace` and :func:`clwave.progressive` calls on the same model,
    device, field and memory cap share (made by the first)."""
    check_field(field)
    cc, cap = ComputeContext.get(device), parse_cap(device_memory)
    return wv.shared(("raytrace", cc.info.id, field, cap),
                     lambda: RayTracer(wv, device=cc, field=field, device_memory=cap))
