"""An OME-TIFF with a channel axis (ZCYX): up to 4 channels are the volume's channels; more are refused naming
what to write instead."""

import numpy as np
import pytest

import clwave
from clwave.cli import main
from clwave.errors import FileFormatError


def test_an_ome_tiff_of_two_channels_is_a_two_channel_volume(tmp_path):
    """Axes ZCYX, 2 channels: each channel the pages that tifffile stores for it, as the volume's last axis; the
    OME physical sizes its spacing."""
    import tifffile

    data = np.arange(5 * 2 * 6 * 7, dtype=np.uint16).reshape(5, 2, 6, 7)
    path = tmp_path / "v.ome.tif"
    tifffile.imwrite(path, data, photometric="minisblack",
                     metadata={"axes": "ZCYX", "PhysicalSizeZ": 2.0, "PhysicalSizeY": 0.5, "PhysicalSizeX": 0.25})
    vol = clwave.load(path)
    assert vol.channels == 2 and vol.spacing == (2.0, 0.5, 0.25)
    for c in range(2):
        np.testing.assert_array_equal(vol.data[..., c], data[:, c].astype(np.float32))


@pytest.mark.parametrize("axes, shape", [("ZCYX", (5, 6, 6, 7)), ("CZYX", (6, 5, 6, 7))])
def test_more_channels_than_a_model_holds_are_refused_naming_the_fix(tmp_path, capsys, monkeypatch, axes, shape):
    """The fix the refusal names slices the channel axis where the file has it, and writes a TIFF that loads: the
    first 4 channels, whichever axis they are on."""
    import tifffile

    path = tmp_path / "six.ome.tif"
    data = np.arange(np.prod(shape), dtype=np.uint16).reshape(shape)
    tifffile.imwrite(path, data, photometric="minisblack", metadata={"axes": axes})
    with pytest.raises(FileFormatError, match=r"6 channels, where clwave models at most 4; write the channels you "
                                              r"want \(up to 4\) to a TIFF of their own") as refused:
        clwave.load(path)
    assert main(["compress", str(path), "-o", str(tmp_path / "o.clw")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(refused.value) in err
    monkeypatch.chdir(tmp_path)
    exec(str(refused.value).split("e.g. ", 1)[1], {"tifffile": tifffile})  # the fix, as the user would run it
    vol = clwave.load(tmp_path / "part.ome.tif")
    channels = np.moveaxis(data, axes.index("C"), -1)[..., :4]
    assert vol.channels == 4
    np.testing.assert_array_equal(vol.data, channels.astype(np.float32))
