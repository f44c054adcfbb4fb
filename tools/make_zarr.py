#!/usr/bin/env python3
"""Write an analytic phantom of any shape to a Zarr store, chunk by chunk: big inputs for benchmarks.

    python tools/make_zarr.py OUT.zarr [--phantom hydrogen|marschner-lobb|shepp-logan] [--shape 1024 | Z,Y,X]
                              [--dtype float32] [--scale 1] [--chunks 128] [--zarr-format 3] [--force]
                              [--ome [--spacing DZ,DY,DX] [--origin X,Y,Z] [--unit micrometer] [--levels 1]]

Each chunk is ``clwave.io.phantoms.phantom_block`` of the whole grid (the phantom's domain cube spans the
grid, each axis its own scale), so a cubic store equals ``clwave.phantom(name, n)`` bit for bit (float32,
scale 1). Chunks are computed and written one per thread of clwave's pool, straight into the store: the
volume is never held, and memory stays at a few chunks (with float64 temporaries of at most 2M voxels each).
``--dtype`` other than float32: the values times ``--scale``, rounded and clipped to the type's range for
integers (e.g. ``--dtype uint16 --scale 65535``).

``--ome`` writes an OME-Zarr multiscale image (NGFF 0.4 in a Zarr v2 store, 0.5 in v3) with axes z, y, x,
``--spacing`` as the scale and the translation that puts the volume's centre at ``--origin`` (clwave's
convention; NGFF's translation is the first voxel's centre), and ``--levels`` levels: level l is the phantom
sampled on a grid of n // 2^l voxels per axis spanning the same box. Without it, the store is one array.

Example: ``python tools/make_zarr.py big.zarr --shape 2048,2048,1024 --dtype uint16 --scale 65535``
(8 GiB of uint16), then ``clwave.load("big.zarr")`` reads it chunk by chunk (docs/chunked.md §1).
"""

from __future__ import annotations

import argparse
import itertools
import shutil
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout

from clwave.io.phantoms import NAMES, phantom_block  # noqa: E402
from clwave.threads import thread_map  # noqa: E402


def numbers(text, count, kind=float):
    values = [kind(v) for v in text.split(",")]
    if len(values) == 1:
        values *= count
    if len(values) != count:
        raise argparse.ArgumentTypeError(f"{text!r}: give 1 or {count} comma-separated numbers")
    return tuple(values)


def write_array(group_or_path, name, phantom, shape, dtype, scale, chunks, zarr_format):
    """Create the array and fill it chunk by chunk; returns it."""
    import zarr

    chunks = tuple(min(c, n) for c, n in zip(chunks, shape))
    if name is None:
        array = zarr.create_array(group_or_path, shape=shape, chunks=chunks, dtype=dtype, zarr_format=zarr_format,
                                  overwrite=True)
    else:
        array = group_or_path.create_array(name, shape=shape, chunks=chunks, dtype=dtype)
    dtype = np.dtype(dtype)

    def write(corner):
        box = tuple(slice(c, min(c + k, n)) for c, k, n in zip(corner, chunks, shape))
        values = phantom_block(phantom, shape, box)
        if dtype.kind in "iu":
            info = np.iinfo(dtype)
            values = np.clip(np.rint(values * np.float64(scale)), info.min, info.max)
        elif scale != 1:
            values = values * np.float64(scale)
        array[box] = values.astype(dtype)

    thread_map(write, itertools.product(*(range(0, n, k) for n, k in zip(shape, chunks))))
    return array


def ngff_multiscales(levels, spacing, origin, unit):
    """NGFF multiscales metadata: levels [(path, shape)], level 0 of voxel size spacing (dz, dy, dx) and
    centre origin (x, y, z); every level spans the same box."""
    centre = np.array(origin[::-1], float)  # (z, y, x)
    n0 = np.array(levels[0][1], float)
    datasets = []
    for path, shape in levels:
        size = np.array(spacing) * n0 / np.array(shape)
        first = centre - size * (np.array(shape) - 1) / 2  # NGFF: the first voxel's centre
        datasets.append({"path": path, "coordinateTransformations": [
            {"type": "scale", "scale": size.tolist()}, {"type": "translation", "translation": first.tolist()}]})
    axes = [{"name": a, "type": "space", **({"unit": unit} if unit else {})} for a in "zyx"]
    return [{"name": "phantom", "axes": axes, "datasets": datasets}]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("out", type=Path, help="the Zarr store to write (a folder)")
    parser.add_argument("--phantom", choices=NAMES, default="hydrogen")
    parser.add_argument("--shape", type=lambda t: numbers(t, 3, int), default=(256, 256, 256),
                        help="N or Z,Y,X voxels (default 256)")
    parser.add_argument("--dtype", default="float32", help="sample type, e.g. float32, uint16 (default float32)")
    parser.add_argument("--scale", type=float, default=1.0, help="values are the phantom's (in [0, 1]) times this")
    parser.add_argument("--chunks", type=lambda t: numbers(t, 3, int), default=(128, 128, 128),
                        help="chunk edge N or Z,Y,X in voxels (default 128)")
    parser.add_argument("--zarr-format", type=int, choices=(2, 3), default=3)
    parser.add_argument("--ome", action="store_true", help="write an OME-Zarr multiscale image")
    parser.add_argument("--spacing", type=lambda t: numbers(t, 3), default=(1.0, 1.0, 1.0),
                        help="--ome: voxel size DZ,DY,DX of level 0 (default 1)")
    parser.add_argument("--origin", type=lambda t: numbers(t, 3), default=(0.0, 0.0, 0.0),
                        help="--ome: world X,Y,Z of the volume's centre (default 0)")
    parser.add_argument("--unit", help="--ome: the unit of length of the axes, e.g. micrometer")
    parser.add_argument("--levels", type=int, default=1, help="--ome: resolution levels (default 1)")
    parser.add_argument("--force", action="store_true", help="replace an existing OUT")
    args = parser.parse_args(argv)
    if min(args.shape) < 2 or min(args.chunks) < 1 or args.levels < 1:
        parser.error("--shape needs >= 2 voxels per axis, --chunks >= 1 and --levels >= 1")
    if not args.ome and (args.levels != 1 or args.unit):
        parser.error("--levels and --unit apply to --ome stores")
    if args.out.exists():
        if not args.force:
            parser.error(f"{args.out} exists; add --force to replace it")
        shutil.rmtree(args.out)

    start = time.perf_counter()
    write = dict(phantom=args.phantom, dtype=args.dtype, scale=args.scale, chunks=args.chunks)
    if args.ome:
        import zarr

        group = zarr.open_group(args.out, mode="w", zarr_format=args.zarr_format)
        levels = [(str(level), tuple(max(2, n >> level) for n in args.shape)) for level in range(args.levels)]
        for path, shape in levels:
            write_array(group, path, shape=shape, zarr_format=args.zarr_format, **write)
        multiscales = ngff_multiscales(levels, args.spacing, args.origin, args.unit)
        if args.zarr_format == 2:
            group.attrs["multiscales"] = [{"version": "0.4", **multiscales[0]}]
        else:
            group.attrs["ome"] = {"version": "0.5", "multiscales": multiscales}
    else:
        write_array(args.out, None, shape=args.shape, zarr_format=args.zarr_format, **write)
    print(f"wrote {args.out}: {args.phantom} {'x'.join(map(str, args.shape))} {args.dtype} in "
          f"{time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    main()
