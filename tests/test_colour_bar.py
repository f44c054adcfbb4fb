"""A colour bar in a saved picture (annot30, trial30's finding 13): ``colour_bar=`` (``--colour-bar``) burns the map's
colours from the window's low end to its high end into an X-ray's picture, top right, labelled with the window's
ends and 0 between them.  Read back from the pixels: the bar's ends and middle against the map's table (matplotlib's,
tests/test_view.py) or the grey levels, labels as white pixels where they belong, the rest of the picture unmoved;
refusals in one line where a colour bar keys nothing."""

import numpy as np
import pytest

from clwave.cli import main
from clwave.errors import InputError
from clwave.io.result import RenderResult
from clwave.model.camera import Camera
from clwave.view.colours import table
from test_outputs_formats import decode_png

H, W = 240, 320
LENGTH = round(0.4 * H)  # the bar's rows: two fifths of the height (draw_colour_bar)


def flat(value=-1.0, channels=1, mode="xray", noise=0.0) -> RenderResult:
    """A result of one value everywhere (plus ``noise``): a background the labels' white stands out on."""
    image = np.full((H, W, channels), value, np.float32)
    image += noise * np.random.default_rng(30).standard_normal(image.shape).astype(np.float32)
    return RenderResult(image, dict(mode=mode, camera=Camera(30, 20, (H, W), extent=90.0).to_dict(), pixel=1.0))


def the_bar(plain, barred) -> tuple:
    """``(column, changed)`` of the colour bar drawn in ``barred`` over ``plain``: the changed column of the most
    distinct values (the gradient's; a label's column has its few anti-aliased levels) and the mask of changed
    pixels."""
    changed = np.any((plain != barred).reshape(H, W, -1), axis=-1)
    flat_rows = barred.reshape(H, W, -1)
    distinct = [len({tuple(v) for v in flat_rows[changed[:, x], x]}) for x in range(W)]
    return int(np.argmax(distinct)), changed


def white(picture, rows, columns, top=255) -> int:
    """The white pixels (every sample at least 75 % of ``top``: the backgrounds here are darker) in a box of
    ``picture``."""
    box = picture.reshape(H, W, -1)[rows, columns].astype(float)
    return int(np.count_nonzero(np.all(box >= 0.75 * top, axis=-1)))


@pytest.mark.parametrize("name", ["viridis", "seismic", "magma_r"])
def test_the_bar_runs_through_the_maps_colours_and_is_labelled(name):
    """A window (-2, 2) about 0: the bar's top row the table's last colour, its bottom the first, its middle (0) the
    table's middle (the rows either side of 127.5, within a row and a half); three labels (2, -2, 0) left of it."""
    result = flat()
    plain = result.picture(window=(-2, 2), colour_map=name)
    barred = result.picture(window=(-2, 2), colour_map=name, colour_bar=True)
    x, changed = the_bar(plain, barred)
    colours = table(name)
    rows = np.nonzero(np.all(barred[:, x] == colours[-1], axis=-1))[0]
    top = int(rows[0])  # the bar's high end: the first row of the table's last colour
    np.testing.assert_array_equal(barred[top + LENGTH - 1, x], colours[0])
    assert not np.array_equal(barred[top + LENGTH, x], colours[0])  # the bar ends there: its rim
    # the two rows about the middle (an even length): the table's rows either side of its middle, 127.5
    above, below = ([i for i in range(256) if np.array_equal(colours[i], barred[top + row, x])]
                    for row in ((LENGTH - 1) // 2, LENGTH // 2))
    assert above and below and min(above) >= 128 > 127 >= max(below) and min(above) - max(below) <= 3
    font = max(12, round(H / 24))
    left = np.s_[: x - font // 2]  # the labels: left of the bar, outside it and its rim
    for row in (top, top + LENGTH // 2, top + LENGTH - 1):
        assert white(barred, np.s_[row - font // 2: row + font // 2], left) > 5, row
    ys, xs = np.nonzero(changed)
    assert xs.min() > W // 2 and ys.max() < H // 2  # the top-right corner alone


@pytest.mark.parametrize("bits, top", [(8, 255), (16, 65535)])
def test_a_grey_bar_climbs_from_black_to_white_and_has_no_zero_label_outside_the_window(bits, top):
    """grey at 8 and 16 bits, a window (1, 3) of one sign: the bar's levels fall from ``top`` (white, 3) to 0 (black,
    1) down its rows, evenly (the middle row half of ``top``, within one level); no label at the middle."""
    result = flat(0.0)
    plain = result.picture(window=(1, 3), bit_depth=bits)
    barred = result.picture(window=(1, 3), bit_depth=bits, colour_bar=True)
    assert barred.dtype == plain.dtype and barred.shape == plain.shape == (H, W)
    x, changed = the_bar(plain, barred)
    start = int(np.argmax(barred[:, x] == top))
    levels = barred[start:start + LENGTH, x].astype(np.int64)
    expected = np.round(top * np.linspace(1.0, 0.0, LENGTH))  # the fractions of the window, an independent ramp
    np.testing.assert_array_equal(levels, expected)
    font = max(12, round(H / 24))
    left = np.s_[: x - font // 2]
    assert white(barred, np.s_[start - font // 2: start + font // 2], left, top) > 5
    assert white(barred, np.s_[start + LENGTH // 2 - font // 2: start + LENGTH // 2 + font // 2], left, top) == 0


def test_nothing_else_in_the_picture_moves_and_the_png_holds_the_bar(tmp_path):
    """A noisy X-ray in seismic with a scale bar too: the picture with the colour bar equals the one without it
    outside the top-right corner the bar and its labels take; the PNG written holds that picture."""
    result = flat(0.0, noise=1.0)
    plain = result.picture(colour_map="seismic", scale_bar=True)
    barred = result.picture(colour_map="seismic", scale_bar=True, colour_bar=True)
    changed = np.any(plain != barred, axis=-1)
    ys, xs = np.nonzero(changed)
    assert xs.min() > W // 2 and ys.max() < H // 2 and changed.sum() > LENGTH * 10
    outside = np.ones((H, W), bool)
    outside[ys.min():ys.max() + 1, xs.min():xs.max() + 1] = False
    np.testing.assert_array_equal(barred[outside], plain[outside])
    result.save(tmp_path / "a.png", colour_map="seismic", scale_bar=True, colour_bar=True)
    np.testing.assert_array_equal(decode_png(tmp_path / "a.png")[1], barred)


@pytest.mark.parametrize("result, options, words", [
    (flat(channels=4, mode="emission-absorption"), {}, "colour_bar=True a shaded image's colours are its transfer "
                                                       "function's, composited along each ray, with no one window of "
                                                       "values: render an X-ray for a colour bar"),
    (flat(channels=2), {}, "colour_bar=True keys a one-channel X-ray's values; this X-ray has 2 channels"),
    (flat(), dict(colour_bar="yes"), "colour_bar='yes' must be True"),
    (RenderResult(np.zeros((30, 30, 1), np.float32), dict(mode="xray")), {}, "the 30x30-pixel picture has no room "
                                                                             "for a colour bar"),
])
def test_a_colour_bar_that_keys_nothing_is_refused(result, options, words):
    with pytest.raises(InputError, match=words):
        result.picture(**{"colour_bar": True, **options})


def test_the_command_line_draws_it_and_refuses_it_before_a_render_where_it_keys_nothing(tmp_path, capsys):
    """``--colour-bar`` (``--colorbar``) on a splat: the PNG differs from the one without it in its top-right corner
    alone; a shaded render, a .tif, a picture too small for it refused in one line (exit 2) before any render (no
    render's report on stdout), nothing written."""
    render = ["render", "phantom:hydrogen:16", "--levels", "1", "--size", "200x240"]
    assert main(render + ["--colour-map", "seismic", "-o", str(tmp_path / "plain.png")]) == 0
    assert main(render + ["--colour-map", "seismic", "--colorbar", "-o", str(tmp_path / "bar.png")]) == 0
    plain, barred = (decode_png(tmp_path / name)[1] for name in ("plain.png", "bar.png"))
    ys, xs = np.nonzero(np.any(plain != barred, axis=-1))
    assert len(ys) > 0 and xs.min() > 120 and ys.max() < 100
    capsys.readouterr()
    shaded = ["render", "phantom:hydrogen:16", "--levels", "1", "--size", "200x240", "--method", "raytrace", "--tf",
              "hydrogen", "--colour-bar"]
    for argv, words in [(shaded + ["-o", str(tmp_path / "s.png")], "--colour-bar a shaded image's colours are its "
                                                                    "transfer function's"),
                        (render + ["--colour-bar", "-o", str(tmp_path / "v.tif")], "--colour-bar sets a .png's "
                                                                                   "colour bar"),
                        (render + ["--colour-bar", "--size", "30", "-o", str(tmp_path / "small.png")],
                         "the 30x30-pixel picture has no room for a colour bar")]:
        assert main(argv) == 2
        out, err = capsys.readouterr()
        assert words in err and err.count("\n") == 1 and "Traceback" not in err and "splatted" not in out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bar.png", "plain.png"]
