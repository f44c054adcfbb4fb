"""Colour maps of X-ray pictures (M1, trial29): ``colour_map=`` (``--colour-map``) colours a one-channel X-ray's grey
levels with the viewer's maps (clwave/view/colours.py, their tables checked against matplotlib in tests/test_view.py),
each reversed as ``NAME_r``: ``grey_r`` shows dark bright, at 8 and 16 bits.  The picture read back against the grey
one (its levels reversed, or looked up in the table), the refusals in one line and before the render."""

import json

import numpy as np
import pytest
from PIL import Image

from clwave.cli import main
from clwave.errors import InputError
from clwave.io.result import RenderResult
from clwave.model.camera import Camera
from clwave.view.colours import table
from test_outputs_formats import decode_png

RENDER = ["render", "phantom:hydrogen:16", "--levels", "1", "--size", "24x20"]


def ramp(channels=1, mode="xray") -> RenderResult:
    """An orthographic result whose values climb from 0 to 1 across it."""
    values = np.linspace(0.0, 1.0, 120 * 90, dtype=np.float32).reshape(120, 90, 1)
    return RenderResult(np.repeat(values, channels, axis=-1),
                        dict(mode=mode, camera=Camera(30, 20, (120, 90), extent=90.0).to_dict(), pixel=1.0))


@pytest.mark.parametrize("bits, top", [(8, 255), (16, 65535)])
def test_grey_r_is_every_level_reversed(bits, top):
    grey = ramp().picture(window=(0, 1), bit_depth=bits)
    for name in ("grey_r", "gray_r"):  # matplotlib's and napari's spelling too
        reversed_ = ramp().picture(window=(0, 1), bit_depth=bits, colour_map=name)
        assert reversed_.dtype == grey.dtype and reversed_.shape == grey.shape
        np.testing.assert_array_equal(reversed_.astype(int), top - grey.astype(int))
    assert reversed_[0, 0] == top and reversed_[-1, -1] == 0  # the least value bright


def test_a_colour_map_and_its_reverse_look_the_grey_levels_up(tmp_path):
    """viridis: each pixel the table's row of its grey level; viridis_r: the row of 255 less it; written as RGB."""
    grey = ramp().picture(window=(0, 1))
    colours = table("viridis")  # matplotlib's (tests/test_view.py)
    np.testing.assert_array_equal(ramp().picture(window=(0, 1), colour_map="viridis"), colours[grey])
    np.testing.assert_array_equal(ramp().picture(window=(0, 1), colour_map="viridis_r"), colours[255 - grey])
    ramp().save(tmp_path / "a.png", window=(0, 1), colour_map="magma_r", scale_bar=10.0)
    _, rgb = decode_png(tmp_path / "a.png")
    assert rgb.shape == (120, 90, 3)
    np.testing.assert_array_equal(rgb[:60], table("magma")[255 - grey][:60])  # above the bar and its label
    with Image.open(tmp_path / "a.png") as im:
        assert im.mode == "RGB"


@pytest.mark.parametrize("result, options, words", [
    (ramp(mode="emission-absorption", channels=4), {}, "a shaded image has its transfer function's colours"),
    (ramp(channels=2), {}, "this X-ray has 2 channels, shown in colours of their own"),
    (ramp(), dict(bit_depth=16), "has 256 colours, for an 8-bit picture: leave out bit_depth=16, or use grey"),
])
def test_a_colour_map_where_it_colours_nothing_is_refused(result, options, words):
    with pytest.raises(InputError, match=words):
        result.picture(colour_map="viridis", **options)


def test_an_unknown_map_and_a_file_of_values_are_refused(tmp_path):
    with pytest.raises(InputError, match=r"colour_map='jet' must be one of grey, bone, .*coolwarm, or one of them "
                                         r"reversed \(_r: e\.g\. grey_r"):
        ramp().picture(colour_map="jet")
    with pytest.raises(InputError, match="colour_map= sets a .png's picture"):
        ramp().save(tmp_path / "a.tif", colour_map="grey_r")
    assert list(tmp_path.iterdir()) == []


def test_the_command_line_reverses_a_render_and_refuses_a_shaded_one_before_it(tmp_path, capsys):
    """``--colour-map grey_r``: the PNG is the grey one's levels reversed; ``--colormap`` the same option; a shaded
    render, a .tif or an unknown map refused in one line (exit 2) before any render, nothing written, and a reversed
    window names the colour map given, reversed (grey_r where none is)."""
    assert main(RENDER + ["-o", str(tmp_path / "grey.png")]) == 0
    assert main(RENDER + ["--colour-map", "grey_r", "-o", str(tmp_path / "r.png")]) == 0
    assert main(RENDER + ["--colormap", "gray_r", "-o", str(tmp_path / "g.png")]) == 0
    grey = decode_png(tmp_path / "grey.png")[1].astype(int)
    for name in ("r.png", "g.png"):
        np.testing.assert_array_equal(decode_png(tmp_path / name)[1], 255 - grey)
    capsys.readouterr()
    shaded = RENDER + ["--method", "raytrace", "--tf", "hydrogen", "--colour-map", "viridis"]
    for argv, words in [(shaded + ["-o", str(tmp_path / "s.png")], "--colour-map viridis colours a one-channel "
                                                                    "X-ray's grey levels; a shaded image"),
                        (RENDER + ["--colour-map", "grey_r", "-o", str(tmp_path / "v.tif")],
                         "--colour-map sets a .png's colours"),
                        (RENDER + ["--colour-map", "jet", "-o", str(tmp_path / "j.png")],
                         "--colour-map jet must be one of grey"),
                        (RENDER + ["--window", "1,-1", "-o", str(tmp_path / "w.png")],  # what trial29 tried
                         "--window 1,-1 must be two finite numbers LO,HI with LO < HI (inverted contrast: "
                         "--colour-map grey_r)"),
                        (RENDER + ["--window", "1,-1", "--colour-map", "seismic", "-o", str(tmp_path / "w.png")],
                         "(inverted contrast: --colour-map seismic_r)"),  # the map given, reversed
                        (RENDER + ["--window", "1,-1", "--colour-map", "magma_r", "-o", str(tmp_path / "w.png")],
                         "(inverted contrast: --colour-map magma)")]:
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert words in err and err.count("\n") == 1 and "Traceback" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["g.png", "grey.png", "r.png"]


def signed_ramp() -> RenderResult:
    """An orthographic X-ray whose values climb from -1 to 3 across it: both signs, not about 0."""
    values = np.linspace(-1.0, 3.0, 120 * 90, dtype=np.float32).reshape(120, 90, 1)
    return RenderResult(values, dict(mode="xray", camera=Camera(30, 20, (120, 90), extent=90.0).to_dict(), pixel=1.0))


@pytest.mark.parametrize("name", ["seismic", "RdBu", "coolwarm", "seismic_r", "RdBu_r", "coolwarm_r"])
def test_a_diverging_map_centres_its_auto_window_on_zero(name):
    """signed30 (trial30's finding 7): "auto" is centred on 0 for a diverging map, so 0 is the table's middle row
    (128 of 256: 0.5 of the way, rounded half to even), the least value below it as far as the greatest above; a
    given window is kept; an image of one sign keeps its percentiles."""
    result = signed_ramp()
    values = result.image[..., 0]
    top = float(np.percentile(values, 99.5))  # the greater end's percentile, as "auto" takes it
    assert result.display_window(colour_map=name) == pytest.approx((-top, top), rel=1e-6)
    assert result.display_window(colour_map="viridis") == pytest.approx(tuple(np.percentile(values, (0.5, 99.5))))
    picture = result.picture(colour_map=name)
    zero = np.unravel_index(np.argmin(np.abs(values)), values.shape)  # the pixel nearest 0 (within half a step)
    assert abs(values[zero]) < 4 / values.size
    np.testing.assert_array_equal(picture[zero], table(name)[128])
    np.testing.assert_array_equal(picture, table(name)[result.picture(window=(-top, top))])
    np.testing.assert_array_equal(result.picture(window=(-1, 1), colour_map=name),
                                  table(name)[result.picture(window=(-1, 1))])  # --window still sets it
    positive = RenderResult(result.image + 2.0, result.meta)
    assert positive.display_window(colour_map=name) == positive.display_window()


def test_the_diverging_maps_are_white_in_the_middle_and_their_ends_as_published():
    """The ends and middle of the tables against the published colours (matplotlib's seismic: dark blue
    (0, 0, 0.3) to dark red (0.5, 0, 0) through white; ColorBrewer's RdBu: #67001f to #053061 through #f7f7f7;
    Moreland's coolwarm: (59, 76, 192) to (180, 4, 38) through (221, 221, 221)), each within one level; the rows
    themselves are checked against matplotlib in tests/test_view.py."""
    published = {"seismic": ((0, 0, 76.5), (255, 255, 255), (127.5, 0, 0)),
                 "RdBu": ((0x67, 0x00, 0x1F), (0xF7, 0xF7, 0xF7), (0x05, 0x30, 0x61)),
                 "coolwarm": ((59, 76, 192), (221, 221, 221), (180, 4, 38))}
    for name, (first, middle, last) in published.items():
        rows = table(name).astype(float)
        assert np.abs(rows[0] - first).max() <= 1 and np.abs(rows[-1] - last).max() <= 1
        assert np.abs((rows[127] + rows[128]) / 2 - middle).max() <= 2
        np.testing.assert_array_equal(table(f"{name}_r"), rows[::-1])


def test_the_command_line_shows_a_signed_volume_in_seismic_about_zero(tmp_path):
    """``--colour-map seismic`` (refused before signed30) on a signed volume: written, its --stats window centred on
    0; ``--window`` keeps the one given."""
    z, y, x = np.mgrid[:12, :12, :12]
    np.save(tmp_path / "amp.npy", (np.sin(x / 2.0) * np.cos(y / 3.0) + 0.3 * np.sin(z / 2.5)).astype(np.float32))
    base = ["render", str(tmp_path / "amp.npy"), "--levels", "1", "--size", "20", "--colour-map", "seismic"]
    assert main(base + ["-o", str(tmp_path / "a.png"), "--stats", str(tmp_path / "a.json")]) == 0
    lo, hi = json.loads((tmp_path / "a.json").read_text())["window"]
    assert lo == -hi and hi > 0
    assert main(base + ["--window=-1,2", "-o", str(tmp_path / "b.png"), "--stats", str(tmp_path / "b.json")]) == 0
    assert json.loads((tmp_path / "b.json").read_text())["window"] == [-1, 2]
    assert decode_png(tmp_path / "a.png")[1].shape == (20, 20, 3)
