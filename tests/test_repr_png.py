"""A render shown in a notebook (trial25 P2): ``RenderResult._repr_png_`` is the PNG of ``picture()`` with its
defaults, decoded here by Pillow and compared with the picture itself, or with its block means where it is reduced."""

import io

import numpy as np
from PIL import Image

from clwave.io.result import REPR_PNG_SIDE, RenderResult


def decoded(result):
    with Image.open(io.BytesIO(result._repr_png_())) as im:
        assert im.format == "PNG"
        return np.asarray(im)


def test_a_small_result_shows_its_picture(rng):
    shaded = RenderResult(rng.uniform(0, 1, (3, 5, 4)).astype(np.float32), {"mode": "shaded"})
    xray = RenderResult(rng.uniform(0, 9, (4, 6, 1)).astype(np.float32), {"mode": "xray"})
    side = RenderResult(rng.uniform(0, 9, (REPR_PNG_SIDE, 7, 1)).astype(np.float32))  # at the cap: not reduced
    for result in (shaded, xray, side):
        np.testing.assert_array_equal(decoded(result), result.picture())


def test_a_large_result_is_reduced_to_the_cap_by_box_averages(rng):
    """1100 x 700 pixels: reduced 3 times (the least whole factor that brings 1100 to 512 or less), each pixel the
    mean of its 3 x 3 block of the picture within one level (Pillow's fixed-point box filter)."""
    result = RenderResult(rng.uniform(0, 1, (700, 1100, 4)).astype(np.float32), {"mode": "shaded"})
    shown, picture = decoded(result), result.picture().astype(float)
    assert shown.shape == (234, 367, 3)
    blocks = picture[:699, :1098].reshape(233, 3, 366, 3, 3).mean(axis=(1, 3))
    assert np.abs(shown[:233, :366] - blocks).max() < 1


def test_a_non_finite_image_shows_as_text():
    assert RenderResult(np.array([[[1.0], [np.nan]]], np.float32))._repr_png_() is None
