"""clwave's warnings name the user's line (errors.warn_outside): the first caller outside the package, however deep
inside clwave the warning is given."""

import sys
import warnings

import dask.array as da
import nibabel as nib
import numpy as np

import clwave
from clwave.errors import ClwaveWarning
from clwave.model.chunked import ChunkedWaveletVolume


def where_warned(call, *args, **kwargs) -> tuple:
    """((filename, line) the one ClwaveWarning of ``call(*args, **kwargs)`` names, (this file, the call's line),
    what the call returned)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        line = sys._getframe().f_lineno + 1
        result = call(*args, **kwargs)
    ours = [w for w in caught if issubclass(w.category, ClwaveWarning)]
    assert len(ours) == 1, [str(w.message) for w in caught]
    return (ours[0].filename, ours[0].lineno), (__file__, line), result


def test_a_loader_note_names_the_line_that_loads(tmp_path):
    """An oblique NIfTI's note, given by the loaders' shared note() two calls below clwave.load."""
    c, s = np.cos(np.radians(30)), np.sin(np.radians(30))
    affine = np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
    nib.save(nib.Nifti1Image(np.ones((8, 8, 8), np.float32), affine), tmp_path / "obl.nii")
    got, want, volume = where_warned(clwave.load, tmp_path / "obl.nii")
    assert got == want and volume.shape == (8, 8, 8)


def test_the_default_levels_note_names_the_line_that_models_in_memory_and_chunked():
    """8 voxels along z allow 2 levels, not the default 3: the note comes through WaveletVolume.from_volume, and for a
    Dask volume through the chunked model's from_volume too."""
    x = np.random.default_rng(0).random((8, 16, 16)).astype(np.float32)
    for volume in (clwave.Volume(x), clwave.Volume(da.from_array(x, chunks=8))):
        got, want, model = where_warned(clwave.WaveletVolume.from_volume, volume)
        assert got == want and model.levels == 2 and isinstance(model, ChunkedWaveletVolume) == volume.chunked


def test_caught_warnings_takes_this_threads_warnings_only_and_nests():
    """errors.caught_warnings (the viewer's render jobs, docs/viewer.md §2): a thread's own warnings into its list,
    not Python's; another thread's, given meanwhile, not (they go to Python's, at their caller's line); an inner
    catch holds its own, the outer one its own again after it."""
    import threading

    from clwave.errors import caught_warnings, warn_outside

    inside, outside = threading.Event(), threading.Event()

    def other():
        inside.wait(10)
        warn_outside(ClwaveWarning("the other thread's"))
        outside.set()

    thread = threading.Thread(target=other)
    with warnings.catch_warnings(record=True) as python:
        warnings.simplefilter("always")
        thread.start()
        with caught_warnings() as outer:
            inside.set()
            assert outside.wait(10)
            warn_outside(ClwaveWarning("first"))
            with caught_warnings() as inner:
                warn_outside("second")
            warn_outside(ClwaveWarning("third"))
        thread.join()
    assert [str(w) for w in outer] == ["first", "third"] and [str(w) for w in inner] == ["second"]
    assert isinstance(inner[0], UserWarning)
    assert [(str(w.message), w.filename) for w in python] == [("the other thread's", __file__)]
