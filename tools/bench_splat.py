"""The bench's wavelet-model and splatting cases (tools/bench.py; docs/benchmarks.md §2, §3, §12): ``decompose``,
``footprints``, ``splat`` (with its streamed and one-shot figures), ``progressive``, and ``orders`` (the basis
order's cost: decomposed, splatted and ray traced)."""

from __future__ import annotations

import statistics
import time

from bench_common import hydrogen_rgba, peak_resident_gib, summary, views  # first: it puts the checkout on sys.path

import clwave
from clwave.device.context import ComputeContext
from clwave.io.phantoms import phantom
from clwave.splat.tables import ViewTables
from clwave.model.transfer import TransferFunction
from clwave.model.wavelet import WaveletVolume


def bench_decompose(args) -> dict:
    vol = phantom("hydrogen", n=args.size)
    tf = TransferFunction.preset("hydrogen")
    stages = {"classify": [], "decompose": [], "threshold": [], "total": []}
    result = None
    for run in range(args.repeats + 1):  # run 0 is the warm-up
        t0 = time.perf_counter()
        rgba = tf.classify(vol)
        t1 = time.perf_counter()
        wv = WaveletVolume.from_volume(rgba, wavelet="cubic", levels=3, transfer_function=tf)
        t2 = time.perf_counter()
        result = wv.threshold(keep=0.05)
        t3 = time.perf_counter()
        if run:
            for name, dt in zip(stages, (t1 - t0, t2 - t1, t3 - t2, t3 - t0)):
                stages[name].append(dt)
    return dict(setting=dict(volume=f"hydrogen {args.size}^3", channels=4, wavelet="cubic", levels=3,
                             keep=0.05, model="approximating"),
                seconds={k: summary(v) for k, v in stages.items()},
                kept=result.kept, compression=result.compression,
                voxels_per_second=args.size ** 3 / statistics.median(stages["total"]),
                target_seconds=4.0)


def bench_splat(args) -> dict:
    vol = phantom("hydrogen", n=args.size)
    full = WaveletVolume.from_volume(vol, wavelet="cubic", levels=3)
    cases = {}
    for keep in args.keep:
        wv = full if keep == 1.0 else full.threshold(keep=keep)
        # single-resolution, and for the thresholded sets coarse bands in coarser framebuffers (docs/splatting.md §4)
        for coarse in (None, 2e-2) if keep < 1.0 else (None,):
            renderer = clwave.SplatRenderer(wv, device=args.device, coarse=coarse)
            for size in (512, 256):
                clwave.splat(wv, clwave.Camera(10.0, 5.0, size=size), renderer=renderer)  # warm-up
                runs = [clwave.splat(wv, clwave.Camera(az, el, size=size), renderer=renderer).meta
                        for az, el in views(args.views)]
                seconds = {k: summary([m["seconds"][k] for m in runs])
                           for k in ("total", "footprints", "binning", "accumulation", "upsampling")}
                updates = statistics.median(m["pixel_updates"] for m in runs)
                name = f"keep {keep:g} at {size}x{size}" + (f", coarse {coarse:g}" if coarse else "")
                cases[name] = dict(
                    coefficients=wv.kept, seconds=seconds, pixel_updates=updates, tile_pairs=statistics.median(
                        m["tile_pairs"] for m in runs),
                    updates_per_second=updates / seconds["accumulation"]["median"],
                    texture_sampling=runs[0]["texture_sampling"], omega_s=runs[0]["omega_s"],
                    framebuffers=runs[0]["framebuffers"])
        cases[f"keep {keep:g}"] = dict(compile_seconds=renderer.compile_seconds)
        for cap in args.device_memory if keep < 1.0 else ():
            cases[f"keep {keep:g} at 512x512, device memory {cap}"] = streamed_splat(wv, cap, args)
        if keep < 1.0:
            cases[f"keep {keep:g} at 512x512, coarse 0.02: one-shot calls"] = one_shot_splat(wv, args)
    return dict(setting=dict(volume=f"hydrogen {args.size}^3 scalar", wavelet="cubic", levels=3,
                             views=args.views, note="each render at a new view, footprints included"),
                targets=dict(keep_0_01_seconds=0.1, keep_0_05_seconds=0.4, full_seconds=8.0,
                             updates_per_second=0.8e9),
                cases=cases)


def streamed_splat(wv, cap, args) -> dict:
    """Seconds a view at 512² within a device-memory cap (single resolution), the chunks streamed."""
    renderer = clwave.SplatRenderer(wv, device=args.device, device_memory=cap)
    clwave.splat(wv, clwave.Camera(10.0, 5.0, size=512), renderer=renderer)  # warm-up
    runs = [clwave.splat(wv, clwave.Camera(az, el, size=512), renderer=renderer).meta for az, el in views(args.views)]
    return dict(coefficients=wv.kept, device_budget=runs[0]["device_budget"],
                chunk_coefficients=runs[0]["chunk_coefficients"],
                coefficient_chunks=statistics.median(m["coefficient_chunks"] for m in runs),
                tile_pairs=statistics.median(m["tile_pairs"] for m in runs),
                seconds={k: summary([m["seconds"][k] for m in runs])
                         for k in ("total", "footprints", "binning", "accumulation", "upload")})


def one_shot_splat(wv, args) -> dict:
    """Wall seconds a call, ``clwave.splat(wv, camera)`` each view (the model keeps the renderer it makes)
    against the same calls with an explicit renderer; the first one-shot call (set-up) apart."""
    cams = [clwave.Camera(az, el, size=512) for az, el in views(args.views)]
    wv.release()
    start = time.perf_counter()
    clwave.splat(wv, clwave.Camera(10.0, 5.0, size=512), device=args.device, coarse=2e-2)
    first = time.perf_counter() - start
    renderer = clwave.SplatRenderer(wv, device=args.device, coarse=2e-2)
    clwave.splat(wv, cams[0], renderer=renderer)  # warm-up
    out = dict(first_call_seconds=first)
    for name, kw in (("one_shot", dict(device=args.device, coarse=2e-2)), ("reused_renderer", dict(renderer=renderer))):
        walls = []
        for cam in cams:
            start = time.perf_counter()
            clwave.splat(wv, cam, **kw)
            walls.append(time.perf_counter() - start)
        out[name] = summary(walls)
    out["ratio"] = out["one_shot"]["median"] / out["reused_renderer"]["median"]
    return out


def bench_footprints(args) -> dict:
    vol = phantom("hydrogen", n=args.size)
    cc = ComputeContext.get(args.device)  # FFT spectra there, as the splat renderer has them
    cases = {}
    for wavelet in ("haar", "linear", "cubic"):
        wv = WaveletVolume.from_volume(vol, wavelet=wavelet, levels=3)
        warm = clwave.Camera(10.0, 5.0, size=512).view(wv)
        ViewTables(wv, 0, [(warm, None)], device=cc)  # warm-up (FFT plans, kernel build)
        seconds, texels = [], []
        for az, el in views(args.views):
            start = time.perf_counter()
            tables = ViewTables(wv, 0, [(clwave.Camera(az, el, size=512).view(wv), None)], device=cc)
            seconds.append(time.perf_counter() - start)
            texels.append(sum(t.data.size for t in tables.textures.values() if t is not None))
        cases[wavelet] = dict(seconds=summary(seconds), textures=sum(t is not None for t in tables.textures.values()),
                              texels=statistics.median(texels), samplings=tables.samplings,
                              texels_per_second=statistics.median(texels) / statistics.median(seconds))
    return dict(setting=dict(volume=f"hydrogen {args.size}^3 scalar", levels=3, image="512x512",
                             views=args.views, note="all levels and subbands of one view, packed for upload"),
                cases=cases)


def bench_progressive(args) -> dict:
    vol = phantom("hydrogen", n=args.size)
    wv = WaveletVolume.from_volume(vol, wavelet="cubic", levels=3).threshold(keep=args.progressive_keep)
    steps, cases = 4, {}
    for coarse in (None, 2e-2):
        renderer = clwave.SplatRenderer(wv, device=args.device, coarse=coarse)
        list(clwave.progressive(wv, clwave.Camera(10.0, 5.0, size=512), steps=steps, renderer=renderer))  # warm-up
        runs = []
        for az, el in views(args.views):
            # all frames first: figures() of an early frame would render the final image inside the timing
            frames = list(clwave.progressive(wv, clwave.Camera(az, el, size=512), steps=steps, renderer=renderer))
            runs.append([f.figures() for f in frames])
        frames = []
        for i, first in enumerate(runs[0]):
            frames.append(dict(kept_of_voxels=first["coefficients"] / wv.n_voxels, coefficients=first["coefficients"],
                               seconds=summary([run[i]["seconds"] for run in runs]),
                               energy=statistics.median(run[i]["energy"] for run in runs),
                               rms_error_vs_final=statistics.median(run[i]["rms_error"] for run in runs)))
        cases["single resolution" if coarse is None else f"coarse {coarse:g}"] = dict(
            compile_seconds=renderer.compile_seconds, frames=frames)
    return dict(setting=dict(volume=f"hydrogen {args.size}^3 scalar", wavelet="cubic", levels=3, image="512x512",
                             keep=args.progressive_keep, steps=steps, views=args.views,
                             note="seconds since the start of the view, footprints included"),
                cases=cases)


def bench_orders(args) -> dict:
    """The cost of the basis order (paper Fig. 14: orders 1, 2, 4, 6): decomposition of the classified hydrogen
    phantom (4 channels, 3 levels), splatting (keep 0.05, 512²) and ray tracing (keep 0.05, 512², tolerance 1e-2)
    per order, the orders interleaved in every repeat so that a loaded machine slows them alike."""
    rgba = hydrogen_rgba(args.size)
    names = ("haar", "linear", "cubic", "quintic")
    cams = [clwave.Camera(az, el, size=512) for az, el in views(args.raytrace_views)]
    decompose, models = {n: [] for n in names}, {}
    for run in range(args.repeats + 1):  # run 0 is the warm-up
        for name in names:
            start = time.perf_counter()
            models[name] = WaveletVolume.from_volume(rgba, wavelet=name, levels=3).threshold(keep=0.05)
            if run:
                decompose[name].append(time.perf_counter() - start)
    out = {}
    for name in names:
        wv = models[name]
        renderer = clwave.SplatRenderer(wv, device=args.device)
        clwave.splat(wv, clwave.Camera(10.0, 5.0, size=512), renderer=renderer)  # warm-up
        splats = [clwave.splat(wv, cam, renderer=renderer).meta for cam in cams]
        case = dict(order=wv.groups[0].wavelet.order, coefficients=wv.kept,
                    decompose_and_threshold_seconds=summary(decompose[name]),
                    splat_seconds=summary([m["seconds"]["total"] for m in splats]),
                    splat_footprint_seconds=summary([m["seconds"]["footprints"] for m in splats]),
                    splat_pixel_updates=statistics.median(m["pixel_updates"] for m in splats))
        out[name] = case
    tracers = {}
    for name in names:
        start = time.perf_counter()
        tracers[name] = clwave.RayTracer(models[name], device=args.device)
        out[name]["raytrace_setup_seconds"] = time.perf_counter() - start
        tracers[name].render(cams[0], tolerance=1e-2)  # warm-up (and the build)
    walls = {n: [] for n in names}
    for cam in cams:  # the orders interleaved per view
        for name in names:
            start = time.perf_counter()
            tracers[name].render(cam, tolerance=1e-2)
            walls[name].append(time.perf_counter() - start)
    for name in names:
        out[name]["raytrace_seconds"] = summary(walls[name])
        out[name]["raytrace_over_cubic"] = summary([a / b for a, b in zip(walls[name], walls["cubic"])])
    del tracers
    out["peak_resident_gib"] = peak_resident_gib()
    return dict(setting=dict(volume=f"hydrogen {args.size}^3 RGBA (preset)", levels=3, keep=0.05, image="512x512",
                             views=args.raytrace_views, tolerance=1e-2), orders=out)


def bench_splat_images(args) -> dict:
    """Splatting's cost per image size (known-gaps §3): Shepp-Logan ``--size``³, cubic, 3 levels, 5 %, one view
    ((30°, 20°) unless ``--views`` asks for more of the spiral) at each ``--images`` size, a renderer reused, single
    resolution and ``coarse=1e-3`` (the CLI's default for 8-bit pictures); per size one warm-up render (its kernel
    builds apart), then ``--repeats`` renders timed in CPU seconds of the process (PoCL's threads included: the
    measure on a loaded machine) and wall seconds, by stage, with the pixel updates and CPU ns per update."""
    import resource

    def cpu():
        usage = resource.getrusage(resource.RUSAGE_SELF)
        return usage.ru_utime + usage.ru_stime

    wv = WaveletVolume.from_volume(phantom("shepp-logan", n=args.size), wavelet="cubic", levels=3).threshold(keep=0.05)
    angles = [(30.0, 20.0)] + views(args.views)[1:]
    cases = {}
    for coarse in (None, 1e-3):
        renderer = clwave.SplatRenderer(wv, device=args.device, coarse=coarse)
        for size in args.images:
            clwave.splat(wv, clwave.Camera(10.0, 5.0, size=size), renderer=renderer)  # warm-up
            runs, cpus = [], []
            for _ in range(args.repeats):
                for az, el in angles:
                    start = cpu()
                    runs.append(clwave.splat(wv, clwave.Camera(az, el, size=size), renderer=renderer).meta)
                    cpus.append(cpu() - start)
            updates = statistics.median(m["pixel_updates"] for m in runs)
            cases[f"{size}x{size}" + (f", coarse {coarse:g}" if coarse else "")] = dict(
                cpu_seconds=summary(cpus), seconds={k: summary([m["seconds"][k] for m in runs])
                                                    for k in ("total", "footprints", "binning", "accumulation",
                                                              "upsampling")},
                pixel_updates=updates, tile_pairs=statistics.median(m["tile_pairs"] for m in runs),
                cpu_ns_per_update=1e9 * statistics.median(cpus) / updates, framebuffers=runs[0]["framebuffers"],
                omega_s=runs[0]["omega_s"], compile_seconds=renderer.compile_seconds)
    return dict(setting=dict(volume=f"shepp-logan {args.size}^3 scalar", wavelet="cubic", levels=3, keep=0.05,
                             views=angles, repeats=args.repeats), cases=cases)
