"""Colour maps of X-ray pictures (M1, trial29): ``colour_map=`` (``--colour-map``) colours a one-channel X-ray's grey
levels with the viewer's maps (clwave/view/colours.py, their tables checked against matplotlib in tests/test_view.py),
each reversed as ``NAME_r``: ``grey_r`` shows dark bright, at 8 and 16 bits.  The picture read back against the grey
one (its levels reversed, or looked up in the table), the refusals in one line and before the render."""

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
    with pytest.raises(InputError, match=r"colour_map='jet' must be one of grey, bone, .*magma_r \(_r: reversed"):
        ramp().picture(colour_map="jet")
    with pytest.raises(InputError, match="colour_map= sets a .png's picture"):
        ramp().save(tmp_path / "a.tif", colour_map="grey_r")
    assert list(tmp_path.iterdir()) == []


def test_the_command_line_reverses_a_render_and_refuses_a_shaded_one_before_it(tmp_path, capsys):
    """``--colour-map grey_r``: the PNG is the grey one's levels reversed; ``--colormap`` the same option; a shaded
    render, a .tif or an unknown map refused in one line (exit 2) before any render, nothing written, and a reversed
    window names the colour map."""
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
                         "--colour-map grey_r)")]:
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert words in err and err.count("\n") == 1 and "Traceback" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["g.png", "grey.png", "r.png"]
