"""Hostile arguments to the Python API, found by fuzz30's driver (docs/known-gaps.md §15): each refused in one line
naming the argument, as a standard exception, where it enters; never an error from deep inside numpy, scipy or
pathlib."""

import numpy as np
import pytest

import clwave
from clwave.errors import InputError


@pytest.fixture(scope="module")
def model():
    data = np.random.default_rng(30).random((8, 9, 10)).astype(np.float32)
    return clwave.WaveletVolume.from_volume(clwave.Volume(data), levels=1)


@pytest.mark.parametrize("path", [3, None, 2.5, [b"x.clw"], b"x.clw"])
@pytest.mark.parametrize("read", [clwave.WaveletVolume.open, clwave.load])
def test_open_and_load_name_a_path_that_is_not_one(read, path):
    with pytest.raises(InputError, match=r"^path must be a file .*got (int|NoneType|float|list|bytes)$"):
        read(path)


@pytest.mark.parametrize("out", [[[0.0]], 3, "out.npy"])
def test_render_many_refuses_an_out_that_is_not_an_array(model, out):
    with pytest.raises(InputError, match=r"^out is a (list|int|str); the views need float32 \(1, 8, 8, 1\)$"):
        clwave.SplatRenderer(model).render_many([clwave.Camera(size=8)], out=out)


@pytest.mark.parametrize("pixel", [1e30, (1.0, 1e300), 2e18])
def test_cone_beam_refuses_a_pixel_beyond_the_world_lengths(pixel):
    """A pixel of 1e30 overflowed a Python int into C while sizing the footprint textures (OverflowError)."""
    with pytest.raises(InputError, match=r"^pixel=.* must be a positive detector spacing.* up to 1e\+18$"):
        clwave.ConeBeam(1000, 1500, 8, pixel=pixel)


def test_cone_beam_takes_a_pixel_at_the_end_of_the_world_lengths():
    assert clwave.ConeBeam(1000, 1500, 8, pixel=1e18).pixel == (1e18, 1e18)


def test_info_shows_a_modality_a_header_gives_by_name_alone(tmp_path, model):
    """A header's modality of a name alone ("CT", which a Volume takes) ended ``clwave info`` in an internal error
    (TypeError: string indices must be integers); now described as the model opened from the file holds it."""
    import json
    import zlib

    import h5py

    from clwave.cli import main
    from clwave.io.clw_info import describe_clw

    path = model.save(tmp_path / "m.clw")
    with h5py.File(path, "r+") as h5:
        header = json.loads(h5.attrs["header"]) | {"modality": "CT"}
        text = json.dumps(header)
        h5.attrs.update(header=text, header_crc32=zlib.crc32(text.encode()))
    assert clwave.WaveletVolume.open(path).modality == {"name": "CT", "units": None}
    assert describe_clw(path)["modality"] == {"name": "CT", "units": None}
    assert main(["info", str(path)]) == 0
