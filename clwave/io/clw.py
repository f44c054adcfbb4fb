"""The ``.clw`` file of a wavelet model (docs/chunked.md §4): an HDF5 file whose coefficients are stored by
importance tier, so that a reader can take the most important ones by reading a prefix, and that a
chunked model can write a block at a time.

Layout (version 2)::

    attrs           format, version, header (JSON: shape, spacing, origin, offset (the model's ``subtracted``),
                    obliquity, value_range (the input's [min, max]; absent in older files), model_error (the
                    whole file's model's RMS error against its input, relative to its largest |value|, where
                    ``clwave compress`` measured it: :func:`record_error`), unit (the world unit, absent: unknown),
                    photo (true: a photo's colour and alpha, not classified; absent: false), noise_sigma (per
                    channel the voxels' noise deviation, null where not noise-like; null or absent: not recorded),
                    levels, channels, groups, ...),
                    header_crc32 (zlib's CRC-32 of the header's UTF-8 bytes)
    content_mask    uint8 (nz, ny, nx): the source volume's non-zero voxels (optional)
    g<i>/occupancy  uint8, bits packed along x: which coarsest-approximation coefficients the content occupies
                    (with the content mask, levels > 0; absent in older files)
    g<i>/positions  int64 (N,): a channel group's stored coefficients, into its band layout, ascending
                    within a run and stored as differences (the first of a run as it is)
    g<i>/values     float32 (N, C); or, quantised, int32 q with attribute ``step``: the values are q * step
    g<i>/runs       int64 (R, 3): (tier, first row, rows) of each run of rows of one tier
    g<i>/detail_field  float64 (2,): the details' energy as a field (levels > 0; absent in older files)

A tier is -1 for the coarsest approximation, else :func:`~clwave.model.chunked.tiers_of` of the
details' importance; a reader takes the runs of the approximation, then of the tiers from the most
important down, as far as it needs.  Zero coefficients are not stored.  Every dataset is chunked,
deflated and checksummed (Fletcher-32), so a damaged file is told apart from a valid one; a quantised
file's positions, values and content mask are compressed with Zstandard (hdf5plugin) instead, its runs
deflated (docs/codecs.md).
"""

from __future__ import annotations

import json
import threading
import zipfile
import zlib
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from ..device.memory import out_of_threads
from ..errors import ClwaveError, FileFormatError, InputError, finite_number
from ..model.bspline import SplineWavelet
from ..model.chunked import ChunkedWaveletVolume, tiers_of
from ..model.mask import ContentMask
from ..model.transform import LARGEST_COEFFICIENT, band_layout
from ..model.budget import check_thresholding, kept_count
from ..model.wavelet import ChannelGroup, WaveletVolume, _top, importance_of
from ..threads import background
from .clw_header import (FILE_FORMAT, FILE_VERSION, MAX_HEADER, check_dataset, checked_header, checked_values,
                         parsed_header, member_rows)
from .detail_field import DetailField
from .files import check_suffix, hdf5_target, write_atomic
from .hdf5_safety import check_self_contained
from .occupancy import OccupancyGrid
from .progress import progress

ROWS = 1 << 14               # coefficients a dataset chunk holds, and a tier's buffer before it is written
READ_ROWS = 256 * ROWS       # coefficients a read of a file takes at most (whole chunks): a step of its bar
MASK_CHUNK = (64, 64, 64)
FILTERS = dict(compression="gzip", compression_opts=4, shuffle=True, fletcher32=True)
ZSTD_LEVEL = 19              # quantised files: Zstandard's strongest ordinary level (docs/codecs.md §2)
INT32_LIMIT = 2 ** 31 - 1
AUTO_FLOOR = 2.0 ** -24      # quantise="auto": a step no finer than float32's resolution of the largest value


def _filters(quantised) -> dict:
    """Per dataset (positions, values, content_mask, runs, occupancy), the HDF5 filters of a float or a quantised
    file: deflate, or Zstandard, which a quantised file's integers favour (measured in docs/codecs.md §2)."""
    if not quantised:
        return dict(positions=FILTERS, values=FILTERS, content_mask=FILTERS, runs=FILTERS, occupancy=FILTERS)
    import hdf5plugin

    zstd = dict(fletcher32=True, **hdf5plugin.Zstd(clevel=ZSTD_LEVEL))
    return dict(positions=dict(shuffle=True, **zstd), values=zstd, content_mask=zstd, runs=FILTERS, occupancy=FILTERS)


# ---------------------------------------------------------------- writing


def write_clw(model, path, overwrite=False, quantise=None) -> Path:
    """Write a :class:`WaveletVolume`, or stream a :class:`ChunkedWaveletVolume`, to ``path`` atomically;
    refuses to replace a file unless ``overwrite``.  ``quantise``: None (exact float32 values), a bound on
    the change of any voxel of :meth:`~WaveletVolume.reconstruct`, or "auto" (:func:`quantisation_steps`)."""
    steps = quantisation_steps(model, quantise)
    return write_atomic(check_suffix(path, (".clw",)), lambda fh: _write(model, fh, steps), overwrite)


def record_error(fh, error):
    """Write ``model_error`` (the RMS over the voxels of the model's difference from its input, relative to the
    input's largest |value|; docs/chunked.md §4) into the header of the ``.clw`` written into ``fh``: it is measured
    from the file as written (a quantised model's rounded values), so it is added before the file is published
    (``Staging.update``).  A model read from the file and thresholded again is another model: its file records
    none."""
    import h5py

    with hdf5_target(fh) as target, h5py.File(target, "r+") as h5:
        header = json.loads(h5.attrs["header"])
        header["model_error"] = float(error)
        text = json.dumps(header)
        h5.attrs.update(header=text, header_crc32=zlib.crc32(text.encode()))


def check_quantise(quantise):
    """None, "auto" or a finite bound > 0 (InputError naming the fix otherwise)."""
    if quantise is None or (isinstance(quantise, str) and quantise == "auto"):
        return quantise
    why = "must be a bound > 0 on the change of any voxel (in the volume's units), or 'auto'"
    try:
        bound = float("nan") if isinstance(quantise, bool) else finite_number(quantise, "quantise")
    except InputError:
        bound = float("nan")
    if not bound > 0:
        raise InputError(f"quantise={quantise!r} {why}", cli=f"--quantise {quantise} {why}")
    return bound


def quantisation_steps(model, quantise) -> list | None:
    """Per channel group, the step its values are rounded to (docs/codecs.md §1), or None unquantised.

    A bound ``E``: step ``2 E / L``, L the synthesis bound (:func:`synthesis_bound`), so no voxel of the
    reconstruction moves by more than E.  "auto": half the smallest stored detail coefficient (largest over
    channels), so no stored coefficient rounds to zero, yet at least float32's resolution of the largest
    value (``AUTO_FLOOR``); an in-memory model only.
    """
    quantise = check_quantise(quantise)
    if quantise is None:
        return None
    chunked = isinstance(model, ChunkedWaveletVolume)
    if quantise == "auto":
        if chunked:
            raise InputError("quantise='auto' needs the coefficients in memory; give a chunked model a bound, "
                             "e.g. quantise=1e-3", cli="--quantise auto needs the whole model in memory; give a "
                                                       "chunked input a bound, e.g. --quantise 1e-3")
        steps = []
        for g in model.groups:
            largest = np.abs(g.values).max(axis=0)
            details = largest[g.band_slices()[0].stop:]
            smallest = details[details > 0] if np.any(details > 0) else largest[largest > 0]
            top = float(largest.max()) if len(largest) else 0.0
            steps.append(max(0.5 * float(smallest.min()), AUTO_FLOOR * top) if len(smallest) else 1.0)
        return steps
    wavelets = [w for w, _ in model.groups()] if chunked else [g.wavelet for g in model.groups]
    steps = [2.0 * quantise / synthesis_bound(w, model.levels) for w in wavelets]
    if not np.all(np.isfinite(steps)):  # 1e308: a step of inf written, then refused by the file's own read
        raise InputError(f"quantise={quantise:g} is too large: its rounding step overflows; give a bound within the "
                         f"volume's values", cli=f"--quantise {quantise:g} is too large: its rounding step overflows; "
                                                 f"give a bound within the volume's values")
    if not chunked:
        for g, step in zip(model.groups, steps):
            _check_range(g.values, step)
    return steps


def synthesis_bound(wavelet, levels) -> float:
    """The most any voxel of :meth:`WaveletVolume.reconstruct` changes when every coefficient changes by at
    most 1: sum over the bands of the largest row sum of |synthesis| (docs/codecs.md §1).  Per band the
    row sum is the product over the axes of the 1-D one (a tensor product): the largest, over the 2^m
    residues, sum of |response| of a level-m scaling function ('a') or wavelet ('d') at the fine level.
    The interpolating model's sampling filter is positive and sums to 1, so the bound holds for it too."""
    bank = wavelet.bank

    def row_sum(letter, m):
        response = np.ones(1)
        for step in range(m):  # m synthesis steps from the coarse coefficient down to the voxels
            up = np.zeros(2 * len(response) - 1)
            up[::2] = response
            response = np.convolve(up, bank["rec_hi" if letter == "d" and step == 0 else "rec_lo"])
        period = 1 << m
        padded = np.append(np.abs(response), np.zeros(-len(response) % period))
        return float(padded.reshape(-1, period).sum(axis=0).max())

    total = row_sum("a", levels) ** 3
    for m in range(1, levels + 1):
        a, d = row_sum("a", m), row_sum("d", m)
        total += (a + d) ** 3 - a ** 3  # the seven detail bands of level m
    return total


def _check_range(values, step):
    """Refuse a step at which some value would not fit an int32."""
    top = float(np.abs(values).max()) if values.size else 0.0
    if top / step > INT32_LIMIT:
        raise InputError(f"a quantisation step of {step:.3g} is too fine for coefficients up to {top:.3g} (their "
                         "multiples must fit in 32 bits); give a larger bound", cli="--quantise: the bound is too "
                         "small for these coefficients (their multiples must fit in 32 bits); give a larger one")


def _write(model, fh, steps):
    import h5py

    chunked = isinstance(model, ChunkedWaveletVolume)
    groups = [(w, c) for w, c in model.groups()] if chunked else [(g.wavelet, g.channels) for g in model.groups]
    header = dict(shape=model.shape, spacing=model.spacing, origin=model.origin, offset=model.subtracted,
                  obliquity=model.obliquity, value_range=model.value_range, unit=model.unit, photo=model.photo,
                  provenance=model.provenance, modality=model.modality,
                  levels=model.levels, channels=model.channels, interpolate=not chunked and model.interpolate,
                  focus=None if model.focus is None else [list(model.focus[0]), model.focus[1]],
                  transfer_function=model.transfer_function, content=model.content, noise_sigma=model.noise_sigma,
                  groups=[dict(wavelet=w.order, channels=list(c)) for w, c in groups])
    with hdf5_target(fh) as target, h5py.File(target, "w", libver="latest", meta_block_size=512) as h5:
        text = json.dumps(header)
        h5.attrs.update(format=FILE_FORMAT, version=FILE_VERSION, header=text, header_crc32=zlib.crc32(text.encode()))
        filters = _filters(steps is not None)
        approximations = [band_layout(w, model.shape, model.levels)[0] for w, _ in groups]
        tiers = _Tiers(h5, [a.size for a in approximations], [len(c) for _, c in groups], steps, filters, target.check,
                       [DetailField(w, model.shape, model.levels) for w, _ in groups] if model.levels > 0 else None)
        # the summary of the content mask the staged tracer's coarse stage reads (docs/chunked.md §4)
        grids = [OccupancyGrid(w, model.levels, a.shape) for (w, _), a in zip(groups, approximations)] \
            if model.levels > 0 and (chunked or model.content_mask is not None) else []
        if chunked:
            _stream(model, h5, tiers, filters, grids)
        else:
            if model.content_mask is not None:
                _write_mask(_mask_dataset(h5, model.shape, filters), model.content_mask, grids)
            for gi, g in enumerate(model.groups):
                stored = np.any(g.values != 0, axis=0)  # a zero coefficient adds nothing: it is not stored
                plain = importance_of(g, None, model.frame)  # tiers rank without the focus (docs/chunked.md §4)
                tiers.append(gi, g.all_positions()[stored], g.values[:, stored], tiers_of(plain[stored]))
        tiers.flush()
        for gi, bits in enumerate(grid.bits for grid in grids):
            h5.create_dataset(f"g{gi}/occupancy", data=bits, **filters["occupancy"],
                              chunks=tuple(min(c, n) for c, n in zip(MASK_CHUNK, bits.shape)))


def _stream(model: ChunkedWaveletVolume, h5, tiers, filters, grids):
    from ..schedulers import client_for

    mask = _mask_dataset(h5, model.shape, filters)
    with client_for(model.scheduler) as client:
        for box, block in model.content_blocks(client):
            mask[box] = block.view(np.uint8)
            for grid in grids:
                grid.add([b.start for b in box], block)
        for gi, positions, values, tier in model.selected(client, tiers=True):
            stored = np.any(values != 0, axis=0)
            tiers.append(gi, positions[stored], values[:, stored], tier[stored])


def _write_mask(data, mask, grids):
    """``mask`` (a ContentMask) into the dataset ``data`` and the occupancy ``grids``, a layer of chunks at a time,
    a byte a voxel only for that layer.  The dataset is closed on return, which writes its cached chunks where the
    streamed writer writes them: the two files stay the same, byte for byte."""
    for z in range(0, mask.shape[0], MASK_CHUNK[0]):
        layer = mask.box((z, 0, 0), (min(MASK_CHUNK[0], mask.shape[0] - z), *mask.shape[1:]))
        data[z:z + len(layer)] = layer.view(np.uint8)
        for grid in grids:
            grid.add((z, 0, 0), layer)


def _mask_dataset(h5, shape, filters):
    return h5.create_dataset("content_mask", shape=shape, dtype=np.uint8,
                             chunks=tuple(min(c, n) for c, n in zip(MASK_CHUNK, shape)), **filters["content_mask"])


class _Tiers:
    """Appends coefficients to their group's datasets in runs of one tier, whole chunks of :data:`ROWS`
    rows at a time (the rest waits in a buffer for more of its tier, or for :meth:`flush`); with ``steps``,
    each group's values as integer multiples of its step; ``check`` raises a failed write (a full disk);
    ``fields``: each group's :class:`~.detail_field.DetailField`, written with the runs."""

    def __init__(self, h5, approx_sizes, channels, steps, filters, check, fields):
        self.h5, self.approx_sizes, self.steps, self.filters, self.check = h5, approx_sizes, steps, filters, check
        self.fields = fields
        self.buffers, self.runs = {}, {gi: [] for gi in range(len(channels))}
        for gi, c in enumerate(channels):
            h5.create_dataset(f"g{gi}/positions", shape=(0,), maxshape=(None,), dtype=np.int64, chunks=(ROWS,),
                              **filters["positions"])
            values = h5.create_dataset(f"g{gi}/values", shape=(0, c), maxshape=(None, c), chunks=(ROWS, c),
                                       dtype=np.float32 if steps is None else np.int32, **filters["values"])
            if steps is not None:
                values.attrs["step"] = np.float64(steps[gi])

    def append(self, gi, positions, values, tiers):
        if self.steps is not None:  # a value that rounds to zero adds nothing: it is not stored
            step = np.float64(self.steps[gi])
            kept = np.any(np.rint(values / step) != 0, axis=0)
            positions, values, tiers = positions[kept], values[:, kept], tiers[kept]
        if self.fields:  # the figure of what a reader gets back, and of the tiers the run table holds
            self.fields[gi].add(positions, values if self.steps is None else np.rint(values / step) * step, tiers)
        names = np.where(positions < self.approx_sizes[gi], -1, tiers)  # the approximation: band 0 of the layout
        for tier in np.unique(names)[::-1]:
            sel = names == tier
            parts = self.buffers.setdefault((gi, int(tier)), [])
            parts.append((positions[sel], values[:, sel]))
            rows = sum(len(p) for p, _ in parts)
            if rows >= ROWS:  # whole chunks now; the rest waits
                held = np.concatenate([p for p, _ in parts]), np.concatenate([v for _, v in parts], axis=1)
                cut = rows - rows % ROWS
                self._write(gi, [(int(tier), [(held[0][:cut], held[1][:, :cut])])])
                self.buffers[(gi, int(tier))] = [(held[0][cut:], held[1][:, cut:])]

    def flush(self):
        """Write what the buffers hold, a group at a time in one write (rewriting a compressed chunk would
        leave its old copy behind as a hole in the file), and each group's runs."""
        for gi in self.runs:
            tiers = sorted((t for g, t in self.buffers if g == gi), key=lambda t: (t != -1, -t))
            self._write(gi, [(t, self.buffers.pop((gi, t))) for t in tiers])
            self.h5.create_dataset(f"g{gi}/runs", data=np.array(self.runs[gi], dtype=np.int64).reshape(-1, 3),
                                   **self.filters["runs"])
            if self.fields:
                self.h5.create_dataset(f"g{gi}/detail_field", data=self.fields[gi].figure())

    def _write(self, gi, tier_parts):
        """Append runs ``[(tier, [(positions, values (C, n)), ...]), ...]`` in one write."""
        if not tier_parts:  # nothing kept (an all-zero model, or every value rounded to 0)
            return
        start = self.h5[f"g{gi}/positions"].shape[0]
        deltas, rows_values = [], []
        for tier, parts in tier_parts:
            positions = np.concatenate([p for p, _ in parts])
            order = np.argsort(positions, kind="stable")  # ascending within a run: small differences deflate well
            deltas.append(np.diff(positions[order], prepend=0))
            rows_values.append(np.concatenate([v for _, v in parts], axis=1).T[order])
            self.runs[gi].append((tier, start + sum(len(d) for d in deltas[:-1]), len(positions)))
        values = np.concatenate(rows_values)
        if self.steps is not None:  # round to the nearest multiple (docs/codecs.md §1)
            _check_range(values, self.steps[gi])
            values = np.rint(values / np.float64(self.steps[gi])).astype(np.int32)
        for name, data in (("positions", np.concatenate(deltas)), ("values", values)):
            dataset = self.h5[f"g{gi}/{name}"]
            dataset.resize(start + len(data), axis=0)
            dataset[start:] = data
        self.check()


# ---------------------------------------------------------------- reading


def read_clw(path, keep=None, approximation=False) -> WaveletVolume:
    """Read a ``.clw`` file written by :func:`write_clw`; with ``keep``, its ``keep`` most important
    coefficients (:meth:`WaveletVolume.open`), read tier by tier; with ``approximation``, the coarsest
    approximation alone (its own tier, read first: the model of the coarsest detail, docs/raytracing.md §8).

    The file is untrusted: its header is checked, and every dataset's shape, type and chunking against
    the header, before anything is read; the checksums are verified as the data is read.  The content mask
    is read when first used, a layer of chunks at a time (:class:`FileMask`).
    """
    path = Path(path)
    if keep is not None:
        keep = check_thresholding(keep, None, None)[0]
    with open_clw(path) as (h5, header):
        shape, levels, channels, groups_header = checked_header(header)
        budget = None if keep is None else kept_count(keep, int(np.prod(shape)))
        frame = (shape, tuple(header["spacing"]), tuple(header["origin"]))
        data = h5.get("content_mask")
        if data is not None:
            check_dataset(data, shape, np.uint8)
        groups = [_read_group(h5, gi, gh, shape, levels, budget, frame, approximation)
                  for gi, gh in enumerate(groups_header)]
        mask = None if data is None else FileMask(path, shape)
    focus = header.get("focus") if keep is None else None  # as threshold(keep=) without a focus
    try:
        return WaveletVolume(shape, header["spacing"], header["origin"], levels, groups, channels,
                             interpolate=header["interpolate"], subtracted=header.get("offset", 0.0),
                             obliquity=header.get("obliquity", 0.0), value_range=header.get("value_range"),
                             unit=header.get("unit"), photo=header.get("photo", False),
                             provenance=header.get("provenance"), modality=header.get("modality"),
                             focus=None if focus is None else (tuple(focus[0]), float(focus[1])),
                             transfer_function=header.get("transfer_function"), content=header.get("content"),
                             content_mask=mask, noise_sigma=header.get("noise_sigma"))
    except (LookupError, ValueError, TypeError) as exc:  # a backstop: checked_header checked what is used here
        raise FileFormatError(f"{path} is inconsistent ({exc}); the file may be corrupt") from None


def read_header(path) -> dict:
    """The header of a ``.clw`` file (shape, spacing, origin, levels, channels, groups, ...), checked as
    :func:`read_clw` checks it, without reading a coefficient: what a reader needs to plan its reading."""
    with open_clw(path) as (_, header):
        checked_header(header)
    return header


@contextmanager
def open_clw(path):
    """The open HDF5 file of a ``.clw`` and its header, for each reader of it (also :mod:`.summary`): any failure,
    there or in the ``with`` block, one line naming the file (:class:`FileFormatError`; out of memory InputError)."""
    import h5py
    import hdf5plugin  # noqa: F401  (registers the Zstandard filter of quantised files)

    path = Path(path)
    if not path.is_file():
        raise FileFormatError(f"{path} does not exist or is not a file")
    if zipfile.is_zipfile(path):
        raise FileFormatError(f"{path} is a .clw file of format version 1 (clwave 0.1), which this clwave no longer "
                              f"reads; compress the volume again to make a version {FILE_VERSION} file")
    try:
        with h5py.File(path, "r") as h5:
            check_self_contained(h5, path, MAX_HEADER)  # nothing outside the file, nothing unbounded
            yield h5, parsed_header(h5, path)
    except ClwaveError:
        raise
    except MemoryError:
        raise InputError(f"{path} holds more than this machine's memory can take; open a part of it "
                         "(keep=, --keep: its most important coefficients)") from None
    except (OSError, ValueError, LookupError, TypeError, RuntimeError) as exc:  # JSONDecodeError: a ValueError
        if out_of_threads(exc):  # the process's limits, not the file's fault
            raise
        raise FileFormatError(f"cannot read {path} as a .clw file ({type(exc).__name__}: "
                              f"{str(exc).splitlines()[0] if str(exc) else 'no detail'}); "
                              "the file may be truncated or corrupt") from None


class FileMask(ContentMask):
    """The content mask of a ``.clw`` file, read when a box of it is first asked for, a layer of the file's
    chunks at a time (packed to bits as it comes): an image that needs a part of the mask, or none of it (a
    splat, the coarsest detail), does not wait for the whole (docs/raytracing.md §8).  Thread-safe."""

    def __init__(self, path, shape):
        super().__init__(shape)  # zeroed pages: no memory until a layer is read
        self.path, self.read = Path(path), np.zeros(-(-self.shape[0] // MASK_CHUNK[0]), bool)
        self.lock = threading.Lock()

    def box(self, start, shape) -> np.ndarray:
        lo, hi = max(int(start[0]), 0), min(int(start[0]) + int(shape[0]), self.shape[0])
        self.load(lo, hi)
        return super().box(start, shape)

    def put(self, start, block):
        self.load(0, self.shape[0])
        super().put(start, block)

    def load(self, lo, hi):
        """Read the layers of chunks that hold layers ``lo .. hi`` of the mask and are not read yet."""
        first, stop = lo // MASK_CHUNK[0], -(-hi // MASK_CHUNK[0])
        if hi <= lo or self.read[first:stop].all():
            return
        import h5py

        with self.lock:
            todo = [c for c in range(first, stop) if not self.read[c]]
            if not todo:
                return
            try:
                with h5py.File(self.path, "r") as h5:
                    data = h5["content_mask"]
                    for c in todo:
                        z = c * MASK_CHUNK[0]
                        self.bits[z:z + MASK_CHUNK[0]] = np.packbits(data[z:z + MASK_CHUNK[0]] != 0, axis=2)
                        self.read[c] = True
            except (OSError, ValueError, KeyError) as exc:
                raise FileFormatError(f"cannot read the content mask of {self.path} ({type(exc).__name__}: "
                                      f"{str(exc).splitlines()[0] if str(exc) else 'no detail'}); the file may "
                                      f"have changed since it was opened, or be corrupt") from None

    def __reduce__(self):  # to a worker: the bits read so far go with it, the rest it reads itself
        return _file_mask, (str(self.path), self.shape, self.bits, self.read)


def _file_mask(path, shape, bits, read) -> FileMask:
    mask = FileMask(path, shape)
    mask.bits, mask.read = bits, read
    return mask


def _read_group(h5, gi, gh, shape, levels, budget, frame, approximation=False) -> ChannelGroup:
    """One channel group: every stored coefficient, or the ``budget`` most important (approximation first,
    then details tier by tier, the last tier cut by importance as :meth:`WaveletVolume.threshold` cuts), or
    with ``approximation`` the approximation's tier alone."""
    wav = SplineWavelet(gh["wavelet"])
    bands = band_layout(wav, shape, levels)
    total, n_approx, c = bands[-1].start + bands[-1].size, bands[0].size, len(gh["channels"])
    runs, stored, stored_values = (h5.get(f"g{gi}/{name}") for name in ("runs", "positions", "values"))
    check_dataset(runs, (member_rows(runs, 2), 3), np.int64)
    n = member_rows(stored, 1)
    check_dataset(stored, (n,), np.int64)
    step = checked_values(stored_values, (n, c))
    runs = runs[...]
    by_start = runs[np.lexsort((runs[:, 2], runs[:, 1]))]  # an empty run (a tier of whole chunks) before its peer
    if n > total or runs.shape[0] > n + 1 or np.any(runs[:, 2] < 0) or np.any(runs[:, 0] < -1) or \
            not np.array_equal(by_start[:, 1], np.cumsum(np.append(0, by_start[:, 2]))[:-1]) or runs[:, 2].sum() != n:
        raise ValueError(f"group {gi}: its runs do not tile its {n} rows (of {total} positions)")
    tiers = sorted(set(runs[:, 0].tolist()), key=lambda t: (t != -1, -t))  # the approximation, then down
    sizes = [int(runs[runs[:, 0] == t, 2].sum()) for t in tiers]
    read, last_cut = (int(tiers[:1] == [-1]), None) if approximation else _tiers_to_read(sizes, budget)
    # in file order (by_start), so that each chunk is inflated once
    wanted = by_start[np.isin(by_start[:, 0], tiers[:read]) & (by_start[:, 2] > 0)]
    run_tiers, spans = wanted[:, 0], wanted[:, 1:]  # (start, count) per run
    positions = _read_rows(stored, spans, np.empty(int(spans[:, 1].sum()), np.int64))
    np.cumsum(positions, out=positions)
    offsets = np.cumsum(spans[:, 1]) - spans[:, 1]  # a run's first difference is its first position
    positions -= np.repeat(np.where(offsets > 0, positions[offsets - 1], 0), spans[:, 1])
    if len(positions):  # the approximation's runs hold positions in its band, the others beyond it
        lo, hi = np.minimum.reduceat(positions, offsets), np.maximum.reduceat(positions, offsets)
        bad = np.where(run_tiers == -1, (lo < 0) | (hi >= n_approx), (lo < n_approx) | (hi >= total))
        if np.any(bad):
            raise ValueError(f"group {gi} tier {run_tiers[bad][0]} holds positions outside its bands")
    # the merge's sort runs while the values are read (a cut of the last tier changes what is merged)
    order = background(np.argsort, positions, kind="stable") if last_cut is None else None
    values = _read_rows(stored_values, spans, np.empty((len(positions), c), stored_values.dtype))
    if step is not None:
        with np.errstate(over="ignore"):  # beyond float32: infinite, refused below
            values = (values * step).astype(np.float32)
    if not np.all(np.isfinite(values)):
        raise ValueError(f"group {gi} holds non-finite values")
    if values.size and not np.abs(values).max() < LARGEST_COEFFICIENT:  # what no transform writes (their energies)
        raise ValueError(f"group {gi} holds coefficients of {np.abs(values).max():.3g}, past the root of float32's "
                         f"largest ({LARGEST_COEFFICIENT:.3g}) that every transform stays below")
    if last_cut is not None:  # the last tier read gives only its most important ``last_cut``
        last = np.repeat(run_tiers == tiers[read - 1], spans[:, 1])
        rows = np.flatnonzero(last)
        rows = rows[np.argsort(positions[rows], kind="stable")]
        part = ChannelGroup(wav, gh["channels"], bands, positions[rows], values[rows].T)
        last[rows[_top(importance_of(part, None, frame), last_cut)]] = False
        positions, values = positions[~last], values[~last]
    parts, order = [(positions, values.T)], None if order is None else order.result()
    del positions, values  # gathered() frees each as its sorted copy is made (the open's peak, docs/chunked.md §4)
    return ChannelGroup.gathered(wav, gh["channels"], bands, parts, order=order)


def _read_rows(dataset, spans, out):
    """Rows ``spans`` ((start, count) per run, in file order, none empty) of a group's dataset into ``out``:
    adjacent runs in one read, so a chunk two runs share is inflated once, cut at multiples of :data:`READ_ROWS`
    (whole chunks), which a bar counts."""
    if not len(spans):
        return out
    ends = spans[:, 0] + spans[:, 1]
    breaks = np.flatnonzero(spans[1:, 0] != ends[:-1]) + 1
    reads = []
    for first, last in zip(np.append(0, breaks), np.append(breaks, len(spans))):
        a, b = int(spans[first, 0]), int(ends[last - 1])
        cuts = [a, *range((a // READ_ROWS + 1) * READ_ROWS, b, READ_ROWS), b]
        reads += zip(cuts[:-1], cuts[1:])
    done = 0
    for a, b in progress(reads, desc=f"reading {dataset.name.lstrip('/')}"):
        dataset.read_direct(out, np.s_[a:b], np.s_[done:done + b - a])
        done += b - a
    return out


def _tiers_to_read(sizes, budget) -> tuple:
    """``(how many tiers, None or how many of the last one to keep)`` for a budget (None: all)."""
    if budget is None:
        return len(sizes), None
    done = 0
    for i, n in enumerate(sizes):
        if done + n >= budget:
            return i + 1, (None if done + n == budget else budget - done)
        done += n
    return len(sizes), None


WaveletVolume.file_format = (read_clw, write_clw)
