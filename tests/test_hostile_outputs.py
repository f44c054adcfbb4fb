"""What a hostile or unlucky user gives the viewer's export (docs/viewer.md §5) and the picture writers
(docs/coordinates.md §3): an input named to break out of the copied command, request bodies that are not UTF-8,
pixel sizes no tag holds, a full disk, a NRRD's micrometres.  Each pins a defect found by attacking them (it failed
before its fix) or a guarantee they keep."""

import asyncio
import json
import logging
import shlex
import subprocess
import sys
from pathlib import Path

import aiohttp
import numpy as np
import pytest

import clwave
from clwave.io.result import RenderResult
from clwave.view import view
from clwave.view.export import Origin, Spec, command, python

from test_view import BASE, decode
from test_view_export import post, shell

#: a name with every character that a shell or a Python literal could take for something else, beginning with "-"
HOSTILE = "-a b'c\"d$(touch pwned)`touch pwned2`$HOME\\\né \u03bc;|&*?.clw"


def test_a_hostile_input_name_and_function_name_make_a_command_that_runs_as_written(tmp_path, monkeypatch):
    """``clwave view -- NAME`` of a .clw whose name begins with "-" and holds spaces, quotes, ``$(...)``, backticks,
    a backslash, a newline and non-ASCII, through a transfer function whose name holds a line "EOF" and ``$(...)``:
    the command runs in bash, reads that file (``./-a...``: until the nineteenth session ``clwave render -a...``, which
    argparse refused as an unknown option), runs nothing of the names, writes the function's ``.json`` whole, and
    renders the picture the Python renders (its literals ``repr``'s)."""
    from clwave.cli import make_parser

    where = tmp_path / "page"
    where.mkdir()
    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=16), levels=1).threshold(keep=0.3)
    wv.save(where / HOSTILE)
    origin = Origin.of_args(make_parser().parse_args(["view", "--size", "16", "--", HOSTILE]))
    assert origin.input == HOSTILE
    tf = clwave.TransferFunction.preset("hydrogen", window=(0.0, 0.5))
    tf = clwave.TransferFunction(tf.points, window=tf.window, name="x\nEOF\n$(touch pwned)'\"")
    camera = clwave.Camera(30.0, 20.0, (16, 20), extent=float(wv.shape[0]))
    spec = Spec("shaded", camera, tolerance=2e-2, tf=tf, levels=1)
    text = command(origin, spec)
    assert text.splitlines()[0] == "cat > view-tf.json <<'EOF'" and text.count("\nEOF\n") == 1
    for name in (HOSTILE, "-h.clw", "-"):  # argparse takes "-h.clw" for an option, a name with a space for none
        words = shlex.split(command(Origin(name), spec).rpartition("\nEOF\n")[2])
        assert Path(make_parser().parse_args(words[1:]).input) == Path(name)
    got = shell(text, where)
    assert not list(where.glob("pwned*")) and not list(Path.cwd().glob("pwned*"))
    written = clwave.TransferFunction.from_dict(json.loads((where / "view-tf.json").read_text()))
    assert written == tf and written.name == tf.name
    monkeypatch.chdir(where)
    exec(compile(python(origin, spec, output="python.png"), "<the viewer's Python>", "exec"), {})
    assert got.std() > 5 and np.array_equal(decode((where / "python.png").read_bytes()), got)


def test_an_input_name_that_is_not_utf8_is_its_bytes_in_the_command():
    """A file name that is no UTF-8 (Python's surrogate escapes): the command is UTF-8 text, as the page and the
    clipboard carry it, and bash reads the name's own bytes from it (``$'\\xff...'``; until the nineteenth session
    the page's text had U+FFFD in its place, another name); the Python's ``repr`` is ASCII and names the same bytes."""
    import os

    name = os.fsdecode(b"\xff\xfe-x y\n$(touch pwned).clw")
    spec = Spec("xray", clwave.Camera(30.0, 20.0, 16, extent=10.0), window=(0.0, 1.0))
    line = command(Origin(name), spec)
    line.encode("utf-8")
    said = subprocess.run(["bash", "-c", f"set -- {line}; printf %s \"$3\""], capture_output=True, timeout=60)
    assert said.returncode == 0 and said.stdout == os.fsencode(name)
    code = python(Origin(name), spec)
    assert code.isascii() and f"clwave.WaveletVolume.open({name!r})" in code


def test_options_given_as_zero_go_into_the_command_and_the_python(tmp_path, monkeypatch):
    """``clwave view f.nii --nan 0 --threshold 0``: both are the command's and the Python's (until the nineteenth
    session ``Origin.of_args`` left out every option whose value was 0, for 0 == False: the command refused the
    volume's NaN voxel, and would have kept 5 % of the coefficients), which render one picture bit for bit."""
    import nibabel

    from clwave.cli import main, make_parser

    volume = np.asarray(clwave.phantom("hydrogen", n=12).data, np.float32)
    volume[0, 0, 0] = np.nan
    nibabel.save(nibabel.Nifti1Image(volume, np.eye(4)), tmp_path / "f.nii")
    origin = Origin.of_args(make_parser().parse_args(["view", str(tmp_path / "f.nii"), "--nan", "0", "--threshold",
                                                      "0", "--levels", "1"]))
    assert {dest: value for dest, _, value in origin.options} == dict(nan=0.0, threshold=0.0, levels=1)
    camera = clwave.Camera(30.0, 20.0, (16, 16), extent=20.0)
    spec = Spec("xray", camera, window=(0.0, 5.0), levels=1)
    words = shlex.split(command(origin, spec))
    assert "--nan" in words and "--threshold" in words
    monkeypatch.chdir(tmp_path)
    assert main(words[1:]) == 0
    got = decode((tmp_path / "view.png").read_bytes())
    exec(compile(python(origin, spec, output="python.png"), "<the viewer's Python>", "exec"), {})
    assert got.std() > 5 and np.array_equal(decode((tmp_path / "python.png").read_bytes()), got)


def test_a_request_body_not_in_utf8_is_one_line_and_odd_values_are_refused(caplog, monkeypatch):
    """``POST /image`` and ``/export`` read their body as UTF-8 JSON whatever charset the request names: bytes that
    are not UTF-8, or a charset Python does not know, are a 400 of one line (until the nineteenth session a 500, its
    traceback logged, from aiohttp's ``request.text()``). Held: NaN, Infinity, a number of 3,000 digits, 2,000 nested
    arrays, a repeated key (the last one read), a forged Host or a null Origin are one line each (400 or 403), the
    server logs no traceback and goes on serving. A saved picture is encoded off the event loop's thread (until the
    nineteenth session on it: every tab's socket held while a 4096² PNG was encoded) and off the render thread."""
    import threading

    from clwave.view import frames

    encoded_on = []

    def encode(picture, lossless):
        if picture.shape[:2] == (8, 24):  # the saved picture's (the server's own frames are square)
            encoded_on.append(threading.current_thread().name)
        return real(picture, lossless)

    real = frames.encode
    monkeypatch.setattr(frames, "encode", encode)
    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=16), levels=1).threshold(keep=0.5)
    good = json.dumps(dict(view=dict(BASE, seq=1), size=[8, 8]))
    view_text = json.dumps(dict(BASE, seq=1))
    refused = {
        "not utf-8": (b'\xff\xfe{"view": 1}', {}),
        "utf-16": (good.encode("utf-16"), {"Content-Type": "application/json; charset=utf-16"}),
        "NaN": ('{"view": %s, "size": [NaN, 8]}' % view_text, {}),
        "Infinity": (good.replace('"azimuth": 30.0', '"azimuth": Infinity'), {}),
        "huge": ('{"view": %s, "size": [%s, 8]}' % (view_text, "9" * 3000), {}),
        "nested": ("[" * 2000 + "]" * 2000, {}),
        "repeated": ('{"view": %s, "size": [8, 8], "size": [9000, 9000]}' % view_text, {}),
        "host": (good, {"Host": "localhost.evil.example"}),
        "origin": (good, {"Origin": "null"}),
    }
    with caplog.at_level(logging.INFO), view(wv, size=16) as v:
        for name, (body, headers) in refused.items():
            async def go():
                async with aiohttp.ClientSession() as s:
                    async with s.post(v.url.replace("/?", "/image?"), data=body, headers=headers) as r:
                        return r.status, await r.read()
            status, line = asyncio.run(go())
            assert status in (400, 403) and line.decode().count("\n") == 1, (name, status, line)
        status, png = post(v, "image", good.replace("[8, 8]", "[8, 24]"),
                           {"Content-Type": "text/plain; charset=x-unknown"})
        assert status == 200 and png.startswith(b"\x89PNG")
        loop_thread = v._background.thread.name
    assert len(encoded_on) == 1 and encoded_on[0] != loop_thread and not encoded_on[0].startswith("clwave-view")
    assert not [r for r in caplog.records if r.exc_info or r.levelno >= logging.ERROR]


@pytest.mark.parametrize("held", [True, False])
def test_a_shaded_save_asked_before_any_tab_looked_makes_its_tracer(tmp_path, held):
    """``POST /image`` of a shaded view from a script, no tab ever having shown one, of a model held or of a .clw file
    (traced in stages): 409 while the tracer (the file's full stage) is made, then the picture (until the nineteenth
    session nothing but a tab's frames started them: 409 for ever)."""
    import time

    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=16), levels=1).threshold(keep=0.5)
    body = dict(view=dict(BASE, seq=1, mode="shaded"), size=[8, 8])
    with view(wv if held else str(wv.save(tmp_path / "h.clw")), size=16) as v:
        deadline, statuses = time.monotonic() + 120, []
        while not statuses or statuses[-1] == 409 and time.monotonic() < deadline:
            status, data = post(v, "image", body)
            statuses.append(status)
            time.sleep(0.2)
    assert set(statuses[:-1]) <= {409} and statuses[-1] == 200 and decode(data).shape == (8, 8, 3)


@pytest.mark.parametrize("pixel", [0.0, 5e-324, float("nan"), float("inf"), -1.0, 1e-30, 1e30])
def test_a_pixel_size_that_no_tag_holds_writes_no_tag(tmp_path, pixel):
    """A pixel of 0, NaN, a denormal, infinite, negative, or too small or large for the tags' 32 bits: the picture
    and the TIFF are written without pHYs or resolution (until the nineteenth session 0 and NaN raised
    ZeroDivisionError and ValueError from ``save``); a pixel of 0.5 mm is 2000 pixels a metre, 20 a centimetre."""
    import png
    import tifffile

    image = np.linspace(0, 1, 64, dtype=np.float32).reshape(8, 8, 1)
    for bits in (8, 16):
        path = RenderResult(image, {"pixel": pixel}).save(tmp_path / f"{bits}.png", bit_depth=bits, unit="mm")
        assert b"pHYs" not in path.read_bytes() and png.Reader(bytes=path.read_bytes()).read()[3]["bitdepth"] == bits
    for unit in ("mm", None):
        path = RenderResult(image, {"pixel": pixel}).save(tmp_path / f"{unit}.tif", unit=unit)
        with tifffile.TiffFile(path) as tif:
            assert "XResolution" not in tif.pages[0].tags or tif.pages[0].tags["XResolution"].value == (1, 1)
            assert np.array_equal(tif.asarray(), image[..., 0])
    held = RenderResult(image, {"pixel": 0.5}).save(tmp_path / "held.png", bit_depth=16, unit="mm")
    assert png.Reader(bytes=held.read_bytes()).read()[3]["physical"] == (2000, 2000, True)
    held = RenderResult(image, {"pixel": 0.5}).save(tmp_path / "held.tif", unit="mm")
    with tifffile.TiffFile(held) as tif:
        assert tif.pages[0].tags["XResolution"].value == (20, 1)


@pytest.mark.parametrize("bits", [8, 16])
def test_a_window_beyond_the_pictures_arithmetic_is_refused_not_drawn_black(bits):
    """An X-ray window whose ends or width are not finite in the picture's arithmetic (float32 for 8 bits, float64 for
    16) is one InputError (until the nineteenth session NaN levels, written as 0 with a RuntimeWarning: the window
    (-1e39, 1e39) drew its middle black, not grey); the widest and narrowest that are hold, without a warning."""
    import warnings

    from clwave.errors import InputError

    result = RenderResult(np.array([-1.0, 0.0, 2.0, 0.0], np.float32).reshape(2, 2, 1))
    top = (1 << bits) - 1
    beyond = [(-1e308, 1e308)] + ([(-1e39, 1e39), (0.0, 5e-324)] if bits == 8 else [])
    for window in beyond:
        with pytest.raises(InputError, match=r"is beyond float"):
            result.picture(window, bit_depth=bits)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert result.picture((-1e38, 1e38), bit_depth=bits).tolist() == [[(top + 1) // 2] * 2] * 2
        assert result.picture((0.0, 1e-45), bit_depth=bits).tolist() == [[0, 0], [top, 0]]


FULL_DISK = """
import resource, sys
import numpy as np
from clwave.errors import OutputError
from clwave.io.result import RenderResult
resource.setrlimit(resource.RLIMIT_FSIZE, (512, resource.getrlimit(resource.RLIMIT_FSIZE)[1]))
image = np.random.default_rng(0).random((32, 32, 1)).astype(np.float32)
for name, bits in (("a.png", 8), ("b.png", 16), ("c.tif", None)):
    try:
        RenderResult(image, {"pixel": 0.5}).save(sys.argv[1] + "/" + name, bit_depth=bits)
    except OutputError as exc:
        print(exc)
"""


def test_a_full_disk_is_one_line_and_leaves_nothing(tmp_path):
    """A file-size limit (as a full disk: the write fails with bytes still in the buffer) is one OutputError line per
    picture and leaves no file; until the nineteenth session an 8-bit PNG, written whole into the buffer, raised the
    bare OSError of the temporary's close over it."""
    import os

    env = dict(os.environ, PYTHONPATH=str(Path(clwave.__file__).parents[1]))
    done = subprocess.run([sys.executable, "-c", FULL_DISK, str(tmp_path)], capture_output=True, text=True, env=env,
                          timeout=120)
    assert done.returncode == 0 and not done.stderr, done.stderr
    lines = done.stdout.splitlines()
    assert len(lines) == 3 and all(line.startswith("cannot write ") and line.endswith("free space") for line in lines)
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("units, unit", [('"µm" "µm" "µm"', "um"), ('"μm" "μm" "μm"', "um"), ('"MM" "mm" "Mm"', "mm"),
                                         ('"mm" "cm" "mm"', None), ('"" "" ""', None)])
def test_a_nrrds_space_units_beyond_ascii_are_read_as_written(tmp_path, units, unit):
    """A NRRD's ``space units`` of micrometres written "µm" (UTF-8, the micro sign or the Greek mu): the world unit is
    "um" (until the nineteenth session pynrrd's ASCII reading dropped the µ, "m": a pHYs a million times off); mixed
    or empty units are no length."""
    from clwave.io.loaders import world_unit

    header = ("NRRD0004\ntype: float\ndimension: 3\nspace: left-posterior-superior\nsizes: 2 2 2\n"
              f"space directions: (1,0,0) (0,1,0) (0,0,1)\nspace units: {units}\nencoding: raw\nendian: little\n\n")
    path = tmp_path / "v.nrrd"
    path.write_bytes(header.encode() + np.zeros(8, np.float32).tobytes())
    assert world_unit(path) == unit
    latin = tmp_path / "latin.nrrd"  # the micro sign in Latin-1: not UTF-8, so no unit rather than metres
    latin.write_bytes(header.replace(units, '"µm" "µm" "µm"').encode("latin-1") + np.zeros(8, np.float32).tobytes())
    assert world_unit(latin) is None
