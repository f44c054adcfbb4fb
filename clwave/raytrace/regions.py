"""Ray tracing on a Dask cluster (docs/raytracing.md §7): the bricks split among the workers into slabs of
brick layers along z, each worker opening the ``.clw`` file itself and tracing the rays through its slab
only; X-ray images are the sums of the slabs' images, emission-absorption images are composited from each
slab's premultiplied colour and transmittance in the order every ray meets the slabs (sort-last
compositing).  Each slab gets an equal share of the tolerance: X-ray images stay within it, composited
colours within it but for what a slab's opacity error dims behind it (docs/raytracing.md §7).
"""

from __future__ import annotations

import numpy as np

from ..cluster import check_model_file, render_parts, workers_of
from ..errors import InputError
from ..io.result import RenderResult
from ..model.geometry import view_in_fine, world_to_fine_affine
from .bricks import BRICK, layout, plan
from .passes import ray_order


def slabs(wv, count: int) -> list:
    """Up to ``count`` runs of brick layers along z, ``[(first, stop)]``, of about equal pool bytes."""
    p = plan(wv)
    bricks, levels, *_ = p.slots()
    lay = layout(wv, bricks, levels)
    sizes = np.bincount(lay["bricks"][:, 0] - p.origin[0], weights=np.diff(lay["ends"]), minlength=p.level.shape[1])
    if not sizes.any():
        return [(int(p.origin[0]), int(p.origin[0] + 1))]
    cuts = np.searchsorted(np.cumsum(sizes) / sizes.sum(), np.arange(1, count) / count, side="right")
    edges = np.unique(np.concatenate([[0], cuts, [len(sizes)]]))
    return [(int(p.origin[0] + a), int(p.origin[0] + b)) for a, b in zip(edges[:-1], edges[1:]) if sizes[a:b].any()]


def check_cluster_model(wv, field):
    """InputError unless ``wv`` can be ray traced on a cluster: opened from a ``.clw`` file, B-spline field."""
    check_model_file(wv, "ray tracing")
    if field != "bspline":
        raise InputError("ray tracing on a Dask cluster takes the B-spline field (field='bspline')")


def raytrace_on_cluster(tracer, wv, camera, client, options: dict, device, device_memory) -> RenderResult:
    """:func:`clwave.raytrace` with ``scheduler=``: one task per slab, each slab on a worker of its own (round
    robin), where the worker keeps its ``tracer`` (the class :class:`~clwave.raytrace.tracer.RayTracer`, which
    calls this module) for later views."""
    workers = workers_of(client)
    parts = slabs(wv, workers)
    share = dict(options, tolerance=options["tolerance"] / len(parts))
    results = render_parts(client, _trace_slab, wv.source, parts, tracer, device, device_memory, camera, share)
    order = slab_order(wv, parts, camera)
    image = composite([results[i][0] for i in order], options["absorption"])
    metas = [m for _, m in results]
    meta = {k: v for k, v in metas[0].items() if k not in ("rays_terminated_early", "segments_per_second",
                                                           "rays_at_simpson_depth_limit", "pool")}
    meta.update(tolerance=options["tolerance"], workers=workers, slabs=[list(r) for r in parts],
                passes=[m["passes"] for m in metas], pool=[m["pool"] for m in metas],
                device_budget=[m["device_budget"] for m in metas])
    for key in ("segments", "segments_shaded_at_midpoint", "integrand_evaluations", "bricks", "brick_pool_bytes",
                "mixed_bricks"):
        meta[key] = int(sum(m[key] for m in metas))
    meta["segments_by_lattice"] = {k: sum(m["segments_by_lattice"][k] for m in metas)
                                   for k in metas[0]["segments_by_lattice"]}
    longest = max(len(m["brick_levels"]) for m in metas)
    meta["brick_levels"] = np.sum([np.pad(m["brick_levels"], (0, longest - len(m["brick_levels"]))) for m in metas],
                                  axis=0).tolist()
    for key in ("render_seconds", "setup_seconds", "compile_seconds"):
        meta[key] = max(m[key] for m in metas)
    return RenderResult(image, meta)


def slab_order(wv, parts, camera) -> list:
    """The slabs ``parts`` in the order every ray of the view meets them (:func:`ray_order` on a grid of slabs)."""
    view = camera.view(wv)
    eye, direction = view_in_fine(view, *world_to_fine_affine(wv.groups[0].wavelet.order, wv.shape, wv.spacing,
                                                              wv.origin))
    eye_slab = np.searchsorted([stop for _, stop in parts], eye[0] / BRICK, side="right")
    return sorted(range(len(parts)), key=lambda i: ray_order([i], eye_slab, direction[:1], view.perspective))


def composite(images: list, absorption: bool) -> np.ndarray:
    """The image of the slabs' images, given front to back: sums (X-ray), or premultiplied colour over colour
    (``C += (1 - A) C_k``, ``A = 1 - (1 - A)(1 - A_k)``)."""
    if not absorption:
        return np.sum(images, axis=0)
    out = np.zeros_like(images[0])
    for img in images:
        out[..., :3] += (1 - out[..., 3:]) * img[..., :3]
        out[..., 3] = 1 - (1 - out[..., 3]) * (1 - img[..., 3])
    return out


def _trace_slab(renderer_of, region, tracer, device, device_memory, camera, options) -> tuple:
    """On a worker: the image of the rays inside one slab, and the meta."""
    renderer = renderer_of(lambda wv, cap: tracer(wv, device=device, device_memory=cap, region=region),
                           device, device_memory)
    result = renderer.render(camera, **options)
    return result.image, result.meta
