"""An X-ray of values of both signs alike (signed30, trial30's finding 3): seismic amplitudes, phase or a difference
cancel along the rays, and the picture is mostly noise; one warning says so and names what to do
(clwave/model/signs.py).  Both sides: a field of both signs warns (splatting, ray tracing's X-ray, the command line
once for a turntable), a positive volume, a noise floor below a positive map and a CT in Hounsfield units do not."""

import warnings

import numpy as np
import pytest

import clwave
from clwave.cli import main
from clwave.model.signs import warn_both_signs

WORDS = "both signs alike (seismic amplitudes, phase, a difference): an X-ray adds them"


def model(data, subtracted=0.0):
    return clwave.WaveletVolume.from_volume(clwave.Volume(np.asarray(data, np.float32) - subtracted,
                                                          subtracted=subtracted), levels=1)


def amplitudes(shape=(12, 12, 12)):
    """Reflectors as a seismic section's: a sine down the first axis, its amplitude varying across."""
    z, y, x = np.mgrid[:shape[0], :shape[1], :shape[2]]
    return np.sin(z / 1.5) * (1 + 0.3 * np.cos(x / 3.0 + y / 4.0))


def told(wv) -> list:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        warn_both_signs(wv)
    return [str(w.message) for w in caught if issubclass(w.category, clwave.ClwaveWarning)]


def test_values_of_both_signs_alike_are_told_and_one_sign_is_not():
    said = told(model(amplitudes()))
    assert len(said) == 1 and WORDS in said[0] and "transfer_function=" in said[0] and "hu_to_mu=True" in said[0]
    lo, hi = amplitudes().min(), amplitudes().max()
    assert f"run from {lo:.4g} to {hi:.4g}" in said[0]
    assert told(model(amplitudes() + 1.5)) == []  # the same, one sign
    assert told(model(amplitudes() - 1.5)) == []  # below 0 throughout: an X-ray of it is the positive one negated
    assert told(model(amplitudes() + 0.8)) == []  # reaches 0.5 below 0 and 2.1 above: under BOTH_SIGNS (0.5)
    assert len(told(model(amplitudes() + 0.4))) == 1  # 0.9 below and 1.7 above: over it
    assert len(told(model(amplitudes() + 1.5, subtracted=1.5))) == 1  # the model's values, after the subtraction
    rgba = clwave.WaveletVolume.from_volume(clwave.Volume(np.repeat(amplitudes()[..., None], 4, -1)
                                                          .astype(np.float32)), levels=1)
    assert told(rgba) == []  # colour channels: not one field's values


def test_a_ct_in_hounsfield_units_is_left_to_its_own_warnings():
    """Air at -1000 about a body of soft tissue (+40) and bone (+1500): both signs, but below 0 on the whole, the
    Hounsfield hint's (and the radiographs' refusal's); subtracting air leaves it positive."""
    ct = np.full((16, 16, 16), -1000.0)
    ct[3:13, 3:13, 3:13] = 40.0
    ct[6:10, 6:10, 6:10] = 1500.0
    assert told(model(ct)) == []
    assert told(model(ct, subtracted=-1000.0)) == []
    body = ct.copy()
    body[ct == -1000.0], body[ct == 1500.0] = -600.0, 1000.0  # no air: no CT in Hounsfield units, so told
    assert len(told(model(body))) == 1


@pytest.mark.opencl
def test_splatting_and_a_ray_traced_xray_warn_and_a_shaded_trace_does_not():
    wv = model(amplitudes())
    camera = clwave.Camera(30, 20, size=12)
    for render in (lambda: clwave.splat(wv, camera), lambda: clwave.raytrace(wv, camera, absorption=False)):
        with pytest.warns(clwave.ClwaveWarning, match="both signs alike"):
            render()
    tf = clwave.TransferFunction([(-1, 0, 0, 1, 0.5), (-0.5, 0, 0, 1, 0), (0.5, 1, 0, 0, 0), (1, 1, 0, 0, 0.5)])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        clwave.raytrace(wv, camera, transfer_function=tf, tolerance=1e-2)
    assert not [w for w in caught if "both signs" in str(w.message)]


@pytest.mark.opencl
def test_the_command_line_warns_once_in_its_words(tmp_path, capsys):
    np.save(tmp_path / "amp.npy", amplitudes().astype(np.float32))
    assert main(["render", str(tmp_path / "amp.npy"), "--levels", "1", "--size", "16", "--turntable", "3",
                 "-o", str(tmp_path / "t.gif")]) == 0
    lines = [line for line in capsys.readouterr().err.splitlines() if "both signs" in line]
    assert len(lines) == 1 and lines[0].startswith("clwave: warning: the model's values run from")
    assert "--method raytrace --tf FILE" in lines[0] and "--subtract VALUE" in lines[0] and "--hu-to-mu" in lines[0]
    np.save(tmp_path / "pos.npy", (amplitudes() + 1.5).astype(np.float32))
    assert main(["render", str(tmp_path / "pos.npy"), "--levels", "1", "--size", "16", "-o",
                 str(tmp_path / "p.png")]) == 0
    assert "both signs" not in capsys.readouterr().err
