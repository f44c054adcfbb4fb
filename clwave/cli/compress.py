"""``clwave compress``: a thresholded wavelet model into a ``.clw`` file."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from .options import add_command, build_model, check_outputs, error_words, file_size, finish, is_clw, kept_words
from .reading import read_volume


def run(args):
    out, = check_outputs(args.force, (args.output, "-o", (".clw",)))
    from ..io.clw import check_quantise
    from ..io.files import published_together

    quantise = args.quantise
    if quantise not in (None, "auto"):
        try:
            quantise = float(quantise)
        except ValueError:
            pass  # check_quantise names it
    quantise = check_quantise(quantise)  # before any work
    volume = None if is_clw(args) else read_volume(args)
    wv, reference = build_model(args, gather=False, volume=volume, noise=True)
    with published_together() as outputs:  # the error measured before the file is published (coordinates.md §4)
        start = time.perf_counter()
        wv.save(out, overwrite=args.force, quantise=quantise)
        saved = time.perf_counter() - start
        error = _error(args, wv, reference, outputs, out, quantise is not None)  # recorded in the file: its size after
        size, voxels = outputs.size(out), wv.n_voxels
        raw = voxels * wv.channels * 4  # the volume the model approximates, as float32
        classified = "" if not args.tf else f", classified to {wv.channels} channels (--tf {args.tf})" \
            if args.classify == "pre" else f", the scalar kept with --tf {args.tf} to classify while ray tracing"
        lines = [f"input                 {args.input}: {' x '.join(map(str, wv.shape[::-1]))} voxels (x, y, z)"
                 f"{classified}{_on_disk(args.input)}",
                 f"model                 {', '.join(dict.fromkeys(wv.wavelets))} wavelets, {wv.levels} "
                 f"level{'s' * (wv.levels != 1)}, {kept_words(wv.kept, wv.n_voxels)}",
                 f"file                  {out}: {file_size(size)}, {_ratios(size, raw, volume)}"
                 f", written in {saved:.2f} s",
                 error]
        finish(outputs, [line for line in lines if line])
    return 0


def _ratios(size, raw, volume) -> str:
    """The file's ``size`` against the input's own (``volume``'s values in the dtype the file stores them in; None:
    a .clw input), and against the volume the model approximates as float32 (``raw`` bytes) where that differs (an
    integer input, or one classified)."""
    against = f"{raw / size:.1f}:1 against the volume as float32 ({file_size(raw)})"
    if volume is None:
        return against
    stored = volume.stored_dtype
    own = math.prod(volume.shape) * volume.channels * stored.itemsize
    mine = f"{own / size:.1f}:1 against the input's {stored} values ({file_size(own)})"
    return mine if own == raw else f"{mine}; {against}"


def _error(args, wv, reference, outputs, out, quantised) -> str | None:
    """The report's line on the model's error against the volume it approximates, recorded in the header of the
    written file ``out`` (``outputs``: the staged outputs; ``quantised``: the file read back from them, for the
    rounded values it holds); None for a .clw input."""
    from ..frames import root_mean_square
    from ..io.clw import read_clw, record_error

    if reference is None:
        return None if is_clw(args) else ("error                 not measured: the input was read chunk by chunk (the "
                                          "error needs it whole)")
    try:
        stored = read_clw(outputs.readable(out)) if quantised else wv  # read by name: h5py and FileMask
        peak = float(np.max(np.abs(reference.data)))
        error = root_mean_square(stored.reconstruct().data - reference.data) / (peak or 1.0)  # squares in float64
    except MemoryError:  # the file is what was asked for; the measure needs the volume twice more
        return ("error                 not measured: not enough memory to rebuild the volume beside it (the file "
                "is complete)")
    outputs.update(out, lambda fh: record_error(fh, error))
    if peak == 0:  # no relative error, no PSNR
        return f"error                 RMS over the voxels {error:.2e}: the volume is zero everywhere"
    return f"error                 {error_words(error)}{_in_noise(wv.noise_sigma, error * peak)}"


def _in_noise(sigmas, rms) -> str:
    """The error ``rms`` (absolute) in units of the input's noise where every channel measured one (docs/model.md §2):
    removing the noise alone gives 1.  Above 1 (r), input = truth + noise and model = truth + e + a * noise (``a`` in
    [0, 1] the share of the noise kept, ``e`` independent of it) give |model - truth| = sqrt(r^2 - 1 + 2a) sigma, at
    least sqrt(r^2 - 1) sigma, where the input is 1 sigma from the truth."""
    if not sigmas or None in sigmas:
        return ""
    sigma = math.sqrt(sum(s * s for s in sigmas) / len(sigmas))
    said = f"; {rms / sigma:.2f} times the input's noise (sigma {sigma:.3g}, measured in the finest band"
    if rms <= sigma:
        return said + ": an error near 1 is mostly noise removed)"
    least = math.sqrt((rms / sigma) ** 2 - 1)
    return (said + f": removing the noise alone gives 1, so the model is at least {least:.2f} sigma from the "
                   f"noise-free volume, where the input is 1; --wavelet linear --noise 3 removes noise)")


def _on_disk(spec) -> str:
    """", N MB on disk" for an input file or folder (nothing for a phantom)."""
    path = Path(spec)
    if spec.startswith("phantom:") or not path.exists():
        return ""
    files = [p for p in path.rglob("*") if p.is_file()] if path.is_dir() else [path]
    return f", {file_size(sum(p.stat().st_size for p in files))} on disk"


def add_parser(sub):
    p = add_command(sub, "compress", "write a thresholded wavelet volume (.clw)", run, "output .clw file")
    p.add_argument("--quantise", help="store the values rounded so that no voxel moves by more than this bound "
                                      "(volume units), or 'auto' (half the smallest kept detail); docs/codecs.md")
