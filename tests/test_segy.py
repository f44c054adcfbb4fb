"""Post-stack SEG-Y cubes (segy30, after trial30): read through segyio, time (or depth) down, inlines along x and
crosslines along y, bins from the trace headers' coordinates; irregular, truncated and too-big files refused in one
line, before the traces are read.

Each file is written here by segyio from a NumPy cube of (time, crossline, inline) samples; the expected volume is
that cube with time reversed (z points up, time down), worked out by hand, never read by the code under test."""

import os
import sys
import time

import numpy as np
import pytest
import segyio

from clwave.cli import main
from clwave.device.memory import HostMemoryError
from clwave.errors import ClwaveWarning, FileFormatError, InputError
from clwave.io.loaders import describe, load
from test_loaders import assert_one_line_error

IEEE, IBM = 5, 1


def write_segy(path, cube, *, fmt=IEEE, crossline_sorted=False, interval=4000, scalar=-100, bins=(25.0, 12.5),
               measurement=1, skip=None, coordinates=True):
    """Write ``cube`` (time, crossline, inline) as a SEG-Y file of inlines 100, 102, ... and crosslines 7, 8, ...,
    its CDP coordinates ``bins`` apart (inline, crossline; a negative crossline bin runs them the other way: a
    left-handed grid on the map) stored times ``scalar`` as SEG-Y scales them; ``skip``: a bin left out."""
    n_t, n_xl, n_il = cube.shape
    spec = segyio.spec()
    spec.format, spec.samples = fmt, np.arange(n_t) * interval / 1000
    spec.ilines, spec.xlines = np.arange(n_il) * 2 + 100, np.arange(n_xl) + 7
    spec.sorting = segyio.TraceSortingFormat.CROSSLINE_SORTING if crossline_sorted else \
        segyio.TraceSortingFormat.INLINE_SORTING
    order = [(i, j) for j in range(n_xl) for i in range(n_il)] if crossline_sorted else \
        [(i, j) for i in range(n_il) for j in range(n_xl)]
    order = [bin_ for bin_ in order if bin_ != skip]
    spec.tracecount = len(order)
    factor = abs(scalar) if scalar < 0 else 1 / scalar
    with segyio.create(str(path), spec) as f:
        for t, (i, j) in enumerate(order):
            x, y = (1000 + i * bins[0], 2000 + j * bins[1]) if coordinates else (0, 0)
            f.header[t] = {segyio.su.iline: int(spec.ilines[i]), segyio.su.xline: int(spec.xlines[j]),
                           segyio.su.cdpx: round(x * factor), segyio.su.cdpy: round(y * factor),
                           segyio.su.scalco: scalar}
            f.trace[t] = np.ascontiguousarray(cube[:, j, i])
        f.bin.update(hdt=interval, hns=n_t, mfeet=measurement)


@pytest.fixture
def cube(rng):
    """(time 9, crossline 4, inline 5) samples that IBM and IEEE floats both hold exactly (sixteenths)."""
    return (rng.integers(-4000, 4000, (9, 4, 5)) / 16).astype(np.float32)


@pytest.mark.parametrize("fmt", [IEEE, IBM])
@pytest.mark.parametrize("crossline_sorted", [False, True])
def test_a_cube_loads_time_down_inlines_along_x_with_its_bins(tmp_path, cube, fmt, crossline_sorted):
    """IEEE and IBM floats (segyio converts IBM), sorted by inline or by crossline: the volume is the cube with time
    reversed (axis 0 is z, up), 4 ms samples 4 m apart (2000 m/s two-way), 25 m inlines, 12.5 m crosslines, metres."""
    write_segy(tmp_path / "c.sgy", cube, fmt=fmt, crossline_sorted=crossline_sorted)
    with pytest.warns(ClwaveWarning, match="4000 apart in its headers .* are 4 apart: time drawn as depth at 2000"):
        vol = load(tmp_path / "c.sgy")
    np.testing.assert_array_equal(vol.data, cube[::-1])
    assert vol.spacing == (4.0, 12.5, 25.0) and vol.unit == "m" and vol.origin == (0.0, 0.0, 0.0)
    assert vol.data.dtype == np.float32 and vol.stored_dtype == np.float32


def test_a_depth_cube_and_spacing_given(tmp_path, cube):
    """A depth cube, 5 m samples stored as SEG-Y stores a depth interval (mm, as µs of time): 5 m apart, down;
    spacing= wins (a time cube drawn at another velocity, an exaggeration), without the note."""
    write_segy(tmp_path / "d.segy", cube, interval=5000, bins=(10.0, 10.0), scalar=1)
    with pytest.warns(ClwaveWarning, match="are 5 apart"):
        vol = load(tmp_path / "d.segy")
    np.testing.assert_array_equal(vol.data, cube[::-1])
    assert vol.spacing == (5.0, 10.0, 10.0)
    vol = load(tmp_path / "d.segy", spacing=(2.0, 10.0, 10.0))  # no warning: the tests' filter makes one an error
    assert vol.spacing == (2.0, 10.0, 10.0)
    np.testing.assert_array_equal(vol.data, cube[::-1])


def test_a_left_handed_grid_is_drawn_as_the_map_and_no_coordinates_are_1(tmp_path, cube):
    """Crosslines running clockwise from the inlines on the map (inline, crossline, up left-handed): crosslines along
    -y, so the picture is not the map's mirror; feet: no unit. No coordinates: bins 1 by 1, warned of."""
    write_segy(tmp_path / "m.sgy", cube, bins=(25.0, -12.5), measurement=2)
    vol = load(tmp_path / "m.sgy", spacing=(4, 12.5, 25))
    np.testing.assert_array_equal(vol.data, cube[::-1, ::-1])
    assert vol.unit is None
    write_segy(tmp_path / "n.sgy", cube, coordinates=False)
    with pytest.warns(ClwaveWarning, match="no CDP or source coordinates .* taken as 1 by 1"):
        vol = load(tmp_path / "n.sgy", spacing=None)
    assert vol.spacing == (4.0, 1.0, 1.0) and vol.unit is None


def test_irregular_truncated_and_huge_files_are_refused_in_one_line(tmp_path, cube):
    """A survey with a bin missing (segyio cannot sort it), a file cut inside a trace, and a regular survey of
    2.1 x 10^9 traces (a sparse file): refused in one line, the last before a trace is read or sorted (and described);
    2^31 and 10^10 traces, more than segyio's 32-bit count: refused."""
    write_segy(tmp_path / "i.sgy", cube, skip=(2, 1))
    with pytest.raises(FileFormatError, match="cannot sort its 19 traces into inlines x crosslines .* regular "
                                              "post-stack survey.*ignore_geometry=True") as e:
        load(tmp_path / "i.sgy")
    assert_one_line_error(e)
    write_segy(tmp_path / "t.sgy", cube)
    os.truncate(tmp_path / "t.sgy", os.path.getsize(tmp_path / "t.sgy") - 10)
    with pytest.raises(FileFormatError, match="not a whole number of traces .* truncated") as e:
        load(tmp_path / "t.sgy")
    assert_one_line_error(e)
    n_il, n_xl, samples = 46_000, 46_000, 64  # 2.1 x 10^9 traces (a sparse file), 542 GB of float32
    write_segy(tmp_path / "h.sgy", np.zeros((samples, 2, 2), np.float32), coordinates=False)
    size = 240 + 4 * samples
    os.truncate(tmp_path / "h.sgy", 3600 + n_il * n_xl * size)
    with open(tmp_path / "h.sgy", "r+b") as fh:  # inline and crossline numbers (bytes 189-196) of the first inline,
        for i, j in [(0, j) for j in range(n_xl)] + [(i, 0) for i in range(n_il)]:  # and of each inline's first
            fh.seek(3600 + (i * n_xl + j) * size + 188)
            fh.write(int(100 + i).to_bytes(4, "big") + int(7 + j).to_bytes(4, "big"))
    start = time.process_time()
    with pytest.raises(HostMemoryError, match="h.sgy's 2,116,000,000 traces of 64 samples needs about 50. GiB") as e:
        load(tmp_path / "h.sgy")
    assert_one_line_error(e)
    assert time.process_time() - start < 5  # the headers alone: 542 GB neither read nor sorted
    facts = describe(tmp_path / "h.sgy")  # info describes it all the same
    assert facts["shape"] == [samples, n_xl, n_il] and facts["stored_shape"] == [n_il, n_xl, samples]
    assert facts["segy"]["inlines"] == [100, 100 + n_il - 1, 1] and facts["spacing"] == [4.0, 1.0, 1.0]
    for traces, problem in ((2 ** 31, "segyio cannot count its traces .* 2.31 or more"),
                            (10 ** 10, "holds 10,000,000,000 traces of 64 samples, which segyio counts 1,410,065,408")):
        os.truncate(tmp_path / "h.sgy", 3600 + traces * size)  # more than segyio's 32-bit count
        with pytest.raises(FileFormatError, match=problem) as e:
            describe(tmp_path / "h.sgy")
        assert_one_line_error(e)
    os.remove(tmp_path / "h.sgy")  # sparse, but 5 TB to a tool that copies it


def test_info_shows_the_survey_and_orientation_is_refused(tmp_path, cube, capsys):
    """clwave info: inline and crossline ranges, samples, interval, format code, sorting, coordinates' scalar, and
    what a sample is in world units; the facts as describe() gives them. orientation= is refused: a SEG-Y cube
    carries its own."""
    write_segy(tmp_path / "c.sgy", cube, fmt=IBM, crossline_sorted=True)
    facts = describe(tmp_path / "c.sgy")
    assert facts["shape"] == [9, 4, 5] and facts["spacing"] == [4.0, 12.5, 25.0] and facts["format"] == "segy"
    survey = facts["segy"]
    assert (survey["inlines"], survey["crosslines"], survey["samples"], survey["interval"]) == \
        ([100, 108, 2], [7, 10, 1], 9, 4000.0)
    assert (survey["format"], survey["sorting"], survey["coordinates"], survey["scalar"]) == (1, "crossline", "CDP",
                                                                                             -100)
    assert main(["info", str(tmp_path / "c.sgy")]) == 0
    out = capsys.readouterr().out
    assert "inlines 100..108 (step 2) along x, crosslines 7..10 (step 1) along y, 9 samples a trace, down" in out
    assert "format 1 (4-byte IBM float), crossline-sorted" in out and "CDP coordinates (scalar -100)" in out
    assert "--spacing 4,12.5,25" in out and "box        125, 50, 36 (x, y, z) m" in out
    with pytest.raises(InputError, match="a segy input is put time .or depth. down, inlines along x, by its own") as e:
        load(tmp_path / "c.sgy", orientation="RAS")
    assert_one_line_error(e)


def test_without_segyio_one_line_names_pip_install(tmp_path, cube, monkeypatch):
    write_segy(tmp_path / "c.sgy", cube)
    monkeypatch.setitem(sys.modules, "segyio", None)  # import segyio raises ImportError
    with pytest.raises(FileFormatError, match="reads with segyio, not installed here: pip install segyio") as e:
        load(tmp_path / "c.sgy")
    assert_one_line_error(e)
