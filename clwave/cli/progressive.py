"""``clwave progressive``: progressive splatting frames as a GIF or a folder of PNGs."""

from __future__ import annotations

import json
from pathlib import Path

from ..errors import InputError
from .options import (add_command, build_model, check_frames_folder, check_outputs, make_camera, parse_device_memory,
                      parse_window, write_gif)


def run(args):
    from ..splat.progressive import check_schedule, progressive
    from ..io.result import RenderResult, resolve_window

    out = Path(args.output)
    as_folder = out.suffix == ""
    if not as_folder and out.suffix.lower() != ".gif":
        raise InputError(f"output {out} must end in .gif, or be a folder name for PNG frames")
    if as_folder:
        check_frames_folder(out, args.force)
    check_outputs(args.force, (None if as_folder else out, "-o", (".gif",)), (args.stats, "--stats", (".json",)))
    camera = make_camera(args)
    steps = 8 if args.steps is None and args.budget is None else args.steps
    check_schedule(steps, args.budget)
    device_memory = parse_device_memory(args)
    wv, _ = build_model(args)
    frames = list(progressive(wv, camera, steps=steps, budget=args.budget, device=args.device,
                              omega_s=args.omega_s, coarse=args.coarse, device_memory=device_memory))
    window = parse_window(args)
    if window == "auto":  # the final image's window for every frame: refinement stays visible
        window = resolve_window(frames[0].final_image()[..., :3], "auto")
    pictures = [RenderResult(f.image, f.meta).to_uint8(window) for f in frames]
    if as_folder:
        out.mkdir(parents=True, exist_ok=True)
        for f, picture in zip(frames, pictures):
            RenderResult(f.image, f.meta).save(out / f"frame_{f.index:03d}.png", window=window, overwrite=True)
    else:
        write_gif(out, pictures, 0.5, args.force)
    figures = [f.figures() for f in frames]
    if args.stats:
        from ..io.files import write_atomic
        text = json.dumps(dict(frames=figures, meta=frames[-1].meta), indent=2, default=str).encode()
        write_atomic(args.stats, lambda fh: fh.write(text), args.force)
    for f in figures:
        print(f"frame {f['index']}: {f['coefficients']:>10,} coefficients ({100 * f['fraction']:6.2f} % of those kept, "
              f"{100 * f['voxel_fraction']:.3f} % of the voxels) at {f['seconds']:.3f} s; error against the final "
              f"image: RMS {f['relative_rms_error']:.2e}, max {f['relative_max_error']:.2e} of its largest value")
    return 0


def add_parser(sub):
    p = add_command(sub, "progressive", "progressive splatting frames as a GIF or a folder of PNGs", run,
                    "output .gif, or a folder for PNG frames", view=True)
    k = p.add_mutually_exclusive_group()
    k.add_argument("--steps", type=int, help="number of frames (default 8)")
    k.add_argument("--budget", type=float, help="seconds: stop when the next step would not fit")
    p.add_argument("--stats", help="per-frame figures as .json")
