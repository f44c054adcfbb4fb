"""Issues #30, #31 and #33 on inputs no other test holds (twenty-first session): data scales far from 1, prime and
non-cubic shapes, anisotropic CT spacing, against independent answers.  Each test pins a case that once broke."""

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

import clwave
from clwave.raytrace.reference import classified_reference

pytestmark = pytest.mark.opencl


def _smooth(shape, seed=7):
    r = gaussian_filter(np.random.default_rng(seed).random(shape), 1.5)
    return (r - r.min()) / np.ptp(r)


@pytest.mark.parametrize("scale", [1e-20, 1e-30])
def test_a_scalar_of_tiny_values_is_shaded(scale):
    # astrophysical densities (1e-24 g/cm^3): the squared world gradients underflowed float32 to 0, every normal was
    # flat and the image lost its diffuse and specular light (0.34 off); normals do not depend on the data's scale
    data = (scale * _smooth((11, 13, 9))).astype(np.float32)
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data, spacing=(1.0, 0.5, 2.0)), levels=1)
    tf = clwave.TransferFunction([(0.0, 1, 1, 1, 0.0), (scale, 1, 0.5, 0, 0.3)])
    cam = clwave.Camera(30, 25, (8, 9))
    tracer = clwave.RayTracer(wv)
    image = tracer.render(cam, transfer_function=tf, tolerance=1e-3).image
    assert np.abs(image - classified_reference(wv, cam, tf, tracer=tracer)).max() <= 1e-3
    unit = clwave.WaveletVolume.from_volume(clwave.Volume(data / np.float32(scale), spacing=(1.0, 0.5, 2.0)), levels=1)
    same = clwave.raytrace(unit, cam, tolerance=1e-3,
                           transfer_function=clwave.TransferFunction([(0.0, 1, 1, 1, 0.0), (1.0, 1, 0.5, 0, 0.3)]))
    assert np.abs(image - same.image).max() <= 1e-4 and image[..., 3].max() > 0.5


def test_a_detail_beyond_the_levels_is_named_as_given():
    # detail=2 on a one-level model was refused as "detail=Detail(level=2, pixels=None) must be ...": not what was given
    vol = clwave.Volume(_smooth((9, 7, 8)).astype(np.float32))
    tracer = clwave.RayTracer(clwave.WaveletVolume.from_volume(vol, levels=1), lod=True)
    with pytest.raises(clwave.InputError, match=r"^detail=2 must be a level from 0 \(full detail\) to 1 "):
        tracer.render(clwave.Camera(20, 30, (4, 4)), detail=2, absorption=False)
    with pytest.raises(clwave.InputError, match=r"^detail=Detail\(level=-1, pixels=None\) must be a level"):
        tracer.render(clwave.Camera(20, 30, (4, 4)), detail=clwave.Detail(-1), absorption=False)


def _cone_rays(cb):
    """Each pixel's unit ray from the source, from ConeBeam's documented geometry alone (coordinates.md §5): the
    pixel (r, c) is (a, b) world units from the principal point, columns along u and rows down v, row 0 at the top."""
    (H, W), (dv, du) = cb.size, cb.pixel
    a = cb.offset[0] + (np.arange(W) + 0.5 - W / 2)[None, :] * du
    b = cb.offset[1] - (np.arange(H) + 0.5 - H / 2)[:, None] * dv
    d = -cb.n + (a / cb.dsd)[..., None] * cb.u + (b / cb.dsd)[..., None] * cb.v
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def test_a_cone_beam_drr_of_hounsfield_units_on_thick_slices_against_a_dense_march(tmp_path):
    """A CT as scanners write it (int16 HU, air -1000, 0.7 x 0.7 x 2.5 mm) through --hu-to-mu's path, a wide cone
    (15 degrees and more) on an off-centre, non-square detector, against Simpson's rule on the model itself
    (WaveletVolume.evaluate, 0.1 mm steps) along rays made here (issue 33: 1e-2 of the image maximum)."""
    shape = (10, 26, 22)
    z, y, x = np.meshgrid(*[np.arange(n) - (n - 1) / 2 for n in shape], indexing="ij")
    body = (x * 0.7 / 7) ** 2 + (y * 0.7 / 8) ** 2 + (z * 2.5 / 11) ** 2 < 1
    hu = np.where(body, 40, -1000).astype(np.int16)
    hu[body & ((x * 0.7 - 2) ** 2 + (y * 0.7 + 1) ** 2 < 6)] = 1200  # a bone
    np.save(tmp_path / "ct.npy", hu)
    vol = clwave.load(tmp_path / "ct.npy", spacing=(2.5, 0.7, 0.7), hu_to_mu=True)
    wv = clwave.WaveletVolume.from_volume(vol, levels=1).threshold(keep=0.3)
    cb = clwave.ConeBeam(45.0, 70.0, (10, 13), pixel=(2.9, 2.3), offset=(4.0, -3.0), azimuth=35, elevation=15,
                         roll=10)
    rays = _cone_rays(cb)
    (H, W) = cb.size
    seen = cb.matrix() @ np.c_[cb.source + 40.0 * rays.reshape(-1, 3), np.ones(H * W)].T  # the rays are the matrix's
    assert np.allclose((seen[:2] / seen[2]).T, np.stack(np.meshgrid(np.arange(W), np.arange(H)), -1).reshape(-1, 2))
    assert np.degrees(np.arccos((-(rays @ cb.n)).min())) > 15
    t = np.linspace(20.0, 70.0, 501)  # 25 mm either side of the isocentre, in 0.1 mm steps: the whole support
    simpson = np.r_[1, np.tile([4, 2], 249), 4, 1] * (t[1] - t[0]) / 3
    values = wv.evaluate((cb.source + t[:, None, None] * rays.reshape(1, -1, 3)).reshape(-1, 3), "bands")
    exact = (simpson @ values.reshape(len(t), -1)).reshape(H, W)
    assert not values.reshape(len(t), -1)[[0, -1]].any()  # the model is zero at both ends of every ray
    image = clwave.splat(wv, cb).image[..., 0]
    assert exact.max() > 0.3 and np.abs(image - exact).max() <= 1e-2 * exact.max()


def test_a_function_that_shows_the_outside_value_is_warned_of(tmp_path):
    # attack26's shell: data of -900 .. -800 under opacity rising from -900, the model 0 beyond the faces (clamped to
    # -800 as classified): an opaque box; the same data with subtract=-1000 and a function transparent there: none
    data = (100 * _smooth((13, 11, 17)) - 900).astype(np.float32)
    tf = clwave.TransferFunction([(-900, .9, .5, .2, 0.0), (-800, .9, .5, .2, 0.4)])
    cam = clwave.Camera(30, 20, 16)
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), levels=1)
    with pytest.warns(clwave.ClwaveWarning, match=r"^the transfer function gives -800, the value the model takes "
                                                  r"beyond the volume's faces .* opacity of 0\.4: .* subtract="):
        clwave.raytrace(wv, cam, transfer_function=tf, shading=False)
    # the box it warns of: its silhouette's corner pixels are nearly opaque, as the pre-classified model's are not
    post = clwave.raytrace(wv, cam, transfer_function=tf, shading=False).image[..., 3]
    pre = clwave.raytrace(clwave.WaveletVolume.from_volume(tf.classify(clwave.Volume(data)), levels=1), cam,
                          shading=False).image[..., 3]
    assert np.abs(post - pre).max() > 0.5
    shifted = clwave.WaveletVolume.from_volume(clwave.load(_npy(tmp_path, data), subtract=-1000), levels=1)
    clear = clwave.TransferFunction([(-850, .9, .5, .2, 0.0), (-800, .9, .5, .2, 0.4)])  # 0 at -1000 (the outside)
    import warnings
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        clwave.raytrace(shifted, cam, transfer_function=clear, shading=False)
    assert not [w for w in seen if "beyond the volume's faces" in str(w.message)]


def _npy(tmp_path, data):
    np.save(tmp_path / "v.npy", data)
    return tmp_path / "v.npy"
