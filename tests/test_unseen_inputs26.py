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


def test_post_classification_sees_only_the_data_within_its_voxel_centres():
    """attack26's shell: data of -900 .. -800 under opacity rising from -900, the model falling to 0 beyond the
    faces through values the data never has (clamped to -800 as classified).  Rays see the data's box only (its
    outermost voxel centres, docs/raytracing.md §10): the box is no longer opaque where the pre-classified model is
    clear, and the kernel agrees with the oracle, which cuts its rays to that box in world units on its own."""
    data = (100 * _smooth((13, 11, 17)) - 900).astype(np.float32)
    tf = clwave.TransferFunction([(-900, .9, .5, .2, 0.0), (-800, .9, .5, .2, 0.4)])
    cam = clwave.Camera(30, 20, 16)
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), levels=1)
    tracer = clwave.RayTracer(wv)
    post = tracer.render(cam, transfer_function=tf, shading=False, tolerance=1e-3).image
    assert np.abs(post - classified_reference(wv, cam, tf, shading=False, tracer=tracer)).max() <= 1e-3
    pre = clwave.raytrace(clwave.WaveletVolume.from_volume(tf.classify(clwave.Volume(data)), levels=1), cam,
                          shading=False).image[..., 3]
    assert post[..., 3].max() > 0.9 and np.abs(post[..., 3] - pre).max() < 0.4  # the shell was 0.93 apart


@pytest.mark.parametrize("background", [0.0, 1e-6])
def test_a_function_that_shows_zero_fogs_the_data_box_whatever_the_bricks(background):
    """attack26's fog: zeros around a 2^3 block of 1 under opacity 0.2 everywhere.  The fog filled the content's
    support box for exact zeros (no bricks where no content reaches) and the model's for 1e-6.  Now both fill the
    data's box and nothing beyond: a ray missing the block crosses the 11 voxel lengths between the outermost centres
    at extinction 0.2 a voxel, 1 - exp(-2.2) of opacity, and the oracle agrees everywhere."""
    data = np.full((12, 12, 12), background, np.float32)
    data[5:7, 5:7, 5:7] = 1
    tf = clwave.TransferFunction([(0, 1, 1, 1, 0.2), (1, 1, 1, 1, 0.2)])
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), levels=1)
    tracer = clwave.RayTracer(wv)
    cam = clwave.Camera(0, 0, 24, extent=20)  # along x: a pixel 20/24 voxel lengths, the centres 5.5 either side
    image = tracer.render(cam, transfer_function=tf, shading=False, tolerance=1e-3).image
    assert np.abs(image - classified_reference(wv, cam, tf, shading=False, tracer=tracer)).max() <= 1e-3
    alpha, inside = image[..., 3], np.abs(np.arange(24) + 0.5 - 12) * 20 / 24 < 5.5
    fog = alpha[np.ix_(inside, inside)]
    assert np.abs(fog[[0, -1]] - (1 - np.exp(-2.2))).max() <= 1e-3 and np.all(fog >= 1 - np.exp(-2.2) - 1e-3)
    assert not alpha[~inside].any() and not alpha[:, ~inside].any()


@pytest.mark.parametrize("preset", ["ct-bone", "ct-soft-tissue"])
def test_hounsfield_units_render_without_subtract(tmp_path, preset):
    """A CT as scanners write it (int16 HU, air -1000 at every face, soft tissue, fat, bone; 2.5 x 0.8 x 0.8 mm),
    post-classified without subtract=: within the tolerance of the oracle, and, no shell at the faces any more, of
    the same CT read with subtract=-1000 (the model the same plus 1000 wherever the faces' zero padding does not
    reach, which the function leaves transparent)."""
    shape = (12, 22, 20)
    z, y, x = np.meshgrid(*[np.arange(n) - (n - 1) / 2 for n in shape], indexing="ij")
    r = (x * 0.8 / 6) ** 2 + (y * 0.8 / 7) ** 2 + (z * 2.5 / 11) ** 2
    hu = np.select([r < 0.7, r < 1], [40, -100], -1000).astype(np.int16)
    hu[(r < 0.7) & ((x * 0.8 - 1) ** 2 + (y * 0.8 + 1.5) ** 2 < 4)] = 1100  # a bone
    path = _npy(tmp_path, hu)
    tf, cam = clwave.TransferFunction.preset(preset), clwave.Camera(35, 25, 16, extent=36)  # both models at one scale
    wv = clwave.WaveletVolume.from_volume(clwave.load(path, spacing=(2.5, 0.8, 0.8)), levels=1)
    tracer = clwave.RayTracer(wv)
    image = tracer.render(cam, transfer_function=tf, tolerance=1e-3).image
    assert image[..., 3].max() > 0.3
    assert np.abs(image - classified_reference(wv, cam, tf, tracer=tracer)).max() <= 1e-3
    shifted = clwave.WaveletVolume.from_volume(clwave.load(path, spacing=(2.5, 0.8, 0.8), subtract=-1000), levels=1)
    assert np.abs(image - clwave.raytrace(shifted, cam, transfer_function=tf, tolerance=1e-3).image).max() <= 2e-3


def _npy(tmp_path, data):
    np.save(tmp_path / "v.npy", data)
    return tmp_path / "v.npy"


def test_fog_in_passes_reaches_regions_without_bricks(monkeypatch):
    """Bricks in a scratch file are traced in passes over regions of bricks; a function that shows the field's 0 is
    seen where no brick lies too, so the passes take the regions of the data's box without bricks as well: random
    content in one half of a long volume, zeros in the other, the same image as the bricks on the device, and the
    zeros' fog 1 - exp(-0.02 * 23) across the 23 voxel lengths between the outermost centres."""
    from clwave.raytrace import bricks

    fits = bricks._check_fits
    monkeypatch.setattr(bricks, "_check_fits", lambda *args: fits(*args) and None)  # never on the device
    shape = (2048, 24, 24)
    data = np.random.default_rng(1).random(shape).astype(np.float32)
    data[shape[0] // 2:] = 0
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), levels=1)
    tf = clwave.TransferFunction([(0, 1, 1, 1, 0.02), (1, 1, 0.5, 0, 0.3)])
    cam = clwave.Camera(90, 0, (64, 5), extent=2100)
    parts = clwave.RayTracer(wv, device_memory="8MiB").render(cam, tolerance=1e-3, transfer_function=tf,
                                                               shading=False)
    monkeypatch.setattr(bricks, "_check_fits", fits)
    whole = clwave.RayTracer(wv).render(cam, tolerance=1e-3, transfer_function=tf, shading=False)
    assert parts.meta["pool"] == "scratch file" and parts.meta["passes"] > 1 and whole.meta["pool"] == "device"
    assert np.abs(parts.image - whole.image).max() <= 1e-3
    assert np.any(np.abs(parts.image[..., 3] - (1 - np.exp(-0.02 * 23))) <= 1e-3)
