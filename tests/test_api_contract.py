"""The Python API used as a demanding library user would (api22): renderers shared by threads, models pickled
for Dask worker processes, array inputs the model must not misread, and arguments of the wrong type refused in one
line naming them (docs/coordinates.md §4)."""

import copy
import pickle
import sys
import threading

import numpy as np
import pytest

import clwave
from clwave.splat.stages import Stages


@pytest.fixture(scope="module")
def rgba_model():
    vol = clwave.phantom("hydrogen", n=20)
    rgba = clwave.TransferFunction.preset("hydrogen").classify(vol)
    return clwave.WaveletVolume.from_volume(rgba, levels=2).threshold(keep=0.2)


CAMERAS = (clwave.Camera(30, 20, size=40), clwave.Camera(100, -10, size=(24, 36)))


def _together(*works):
    """Each of ``works`` run in a thread of its own, all at once, the threads taking turns often: what a race there
    is shows in a few views."""
    threads = [threading.Thread(target=work) for work in works]
    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-5)
    try:
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    finally:
        sys.setswitchinterval(interval)


def _in_two_threads(render, other=None):
    """Two threads render both cameras three times each, alternately, the first by ``render``, the second by
    ``other`` (default ``render``); the images, per camera."""
    images = {0: [], 1: []}

    def work(first, draw):
        for k in range(6):
            which = (first + k) % 2
            images[which].append(draw(CAMERAS[which]))

    _together(lambda: work(0, render), lambda: work(1, other or render))
    return images


def _renderer(model, kind):
    """A new renderer's ``camera -> image``."""
    if kind == "splat":
        renderer = clwave.SplatRenderer(model)
        return lambda camera: renderer.render(camera).image
    tracer = clwave.RayTracer(model)
    return lambda camera: tracer.render(camera, tolerance=1e-2).image


@pytest.mark.parametrize("kind", ["splat", "raytrace"])
@pytest.mark.parametrize("renderers", ["one", "two"])
def test_renderers_used_by_two_threads_render_each_view_as_alone(rgba_model, kind, renderers):
    """Two threads rendering at once, through one renderer or one each: every image is bit for bit the one a
    renderer gives the view alone.  Until api22 a SplatRenderer's views shared its buffers, and every renderer of a
    device its kernels, whose arguments another thread's launch overwrote: NaN or wrong images (up to 4e32), or a
    segmentation fault; renders on a device now take their turn (threads.one_at_a_time)."""
    render = _renderer(rgba_model, kind)
    alone = [render(camera) for camera in CAMERAS]
    images = _in_two_threads(render, None if renderers == "one" else _renderer(rgba_model, kind))
    for which, expected in enumerate(alone):
        assert len(images[which]) == 6
        for image in images[which]:
            np.testing.assert_array_equal(image, expected)


def test_one_shot_splats_from_two_threads_share_the_models_renderer_safely(rgba_model):
    alone = [clwave.SplatRenderer(rgba_model).render(camera).image for camera in CAMERAS]
    images = _in_two_threads(lambda camera: clwave.splat(rgba_model, camera).image)
    for which, expected in enumerate(alone):
        for image in images[which]:
            np.testing.assert_array_equal(image, expected)


@pytest.fixture(scope="module")
def dense_model():
    """Every coefficient of noise kept: a ray tracer's set-up launches many kernels."""
    data = np.random.default_rng(1).random((24, 24, 24, 4)).astype(np.float32) * 0.2
    return clwave.WaveletVolume.from_volume(clwave.Volume(data), "cubic", levels=2)


def test_ray_tracers_set_up_in_two_threads_at_once_hold_the_bricks_of_one_alone(dense_model):
    """Set-ups share the device's kernels: until thread22 their launches (and pyopencl's fill kernel) took another
    thread's arguments, so that bricks were wrong (by up to 0.18, or 8e33) or PoCL aborted the process."""
    alone = clwave.RayTracer(dense_model).bricks.pool.get()
    pools = _in_two_threads(lambda camera: clwave.RayTracer(dense_model).bricks.pool.get())
    assert len(pools[0]) == len(pools[1]) == 6
    for pool in pools[0] + pools[1]:
        np.testing.assert_array_equal(pool, alone)


def test_one_shot_ray_traces_from_two_threads_on_a_fresh_model_build_one_tracer(dense_model, monkeypatch):
    """Until thread22 both threads built the model's tracer (``WaveletVolume.shared`` had no lock), at once."""
    made = []
    init = clwave.RayTracer.__init__
    monkeypatch.setattr(clwave.RayTracer, "__init__", lambda self, *a, **k: made.append(init(self, *a, **k)))
    alone = clwave.raytrace(copy.deepcopy(dense_model), CAMERAS[0], tolerance=1e-2).image
    for k in range(1, 4):
        fresh, images = copy.deepcopy(dense_model), []  # keeps no tracer
        _together(*[lambda: images.append(clwave.raytrace(fresh, CAMERAS[0], tolerance=1e-2).image)] * 2)
        assert len(made) == 1 + k and len(images) == 2
        for image in images:
            np.testing.assert_array_equal(image, alone)


def test_a_progressive_view_splats_with_its_own_buffers_while_another_thread_renders(monkeypatch):
    """Another thread's view begun between two frames of a progressive one replaces the renderer's per-splat buffers:
    until thread22 the perspective view's later passes wrote float4 centres into the orthographic view's float2 buffer
    (past its end).  Each pass is checked to get buffers of its own view's shape, and every image to be as alone."""
    data = np.random.default_rng(3).random((16, 16, 16)).astype(np.float32)
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), "cubic", levels=2)
    r = clwave.SplatRenderer(wv)
    perspective, ortho = clwave.Camera(30, 20, size=24, perspective=True), clwave.Camera(60, 10, size=24)
    alone = [frame.image for frame in clwave.progressive(wv, perspective, steps=4, renderer=r)]
    alone_ortho = r.render(ortho).image
    project, wrong = Stages.project, []

    def checked(self, n, first, coef, tables, centre, *rest):
        if centre.shape[0] < n or centre.shape[1] != (4 if self.perspective else 2):
            wrong.append((self.perspective, centre.shape))
        return project(self, n, first, coef, tables, centre, *rest)

    monkeypatch.setattr(Stages, "project", checked)
    views, orthos, done = [], [], threading.Event()

    def progressive():
        for _ in range(4):
            views.append([frame.image for frame in clwave.progressive(wv, perspective, steps=4, renderer=r)])
        done.set()

    def other():
        while not done.is_set():
            orthos.append(r.render(ortho).image)

    _together(progressive, other)
    assert wrong == [] and len(views) == 4 and orthos
    for frames in views:
        assert len(frames) == len(alone)
        for frame, expected in zip(frames, alone):
            np.testing.assert_array_equal(frame, expected)
    for image in orthos:
        np.testing.assert_array_equal(image, alone_ortho)


def test_a_rendered_model_pickles_and_renders_the_same(rgba_model):
    """A model that one-shot calls have rendered keeps their renderers (OpenCL objects, which do not pickle): it
    pickles and deep-copies without them, as a Dask worker process receives it ("cannot pickle 'Device' object"
    before api22), and the copy renders the same image."""
    expected = clwave.splat(rgba_model, CAMERAS[0]).image  # rgba_model now holds its shared renderer
    for twin in (pickle.loads(pickle.dumps(rgba_model)), copy.deepcopy(rgba_model)):
        assert len(twin._shared) == 0 and len(rgba_model._shared)
        np.testing.assert_array_equal(clwave.splat(twin, CAMERAS[0]).image, expected)


def _coefficients(data):
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), wavelet="linear", levels=1)
    return np.concatenate([g.values.ravel() for g in wv.groups])


def test_masked_voxels_are_refused_not_rendered_with_their_stored_values():
    """numpy.asarray of a masked array keeps the masked voxels' stored values (a fill of 1e20, or whatever was
    there): the model was made of them, silently, before api22."""
    data = np.random.default_rng(1).random((6, 7, 8))
    stored = data.copy()
    stored[data > 0.9] = 7.0
    with pytest.raises(clwave.InputError, match=r"masked array with \d+ masked voxel.*data\.filled\(0\)"):
        clwave.Volume(np.ma.masked_array(stored, mask=data > 0.9))
    unmasked = np.ma.masked_array(data, mask=False)  # a mask that masks nothing is the data
    np.testing.assert_array_equal(_coefficients(unmasked), _coefficients(data))
    wv = clwave.WaveletVolume.from_volume(clwave.Volume(data), wavelet="linear", levels=1)
    points = np.ma.masked_array(np.zeros((4, 3)), mask=[[0, 0, 0], [1, 0, 0], [0, 0, 0], [0, 0, 0]])
    for method in (wv.evaluate, wv.gradient):
        with pytest.raises(clwave.InputError, match=r"points is a masked array with 1 masked value"):
            method(points)


@pytest.mark.parametrize("layout", ["fortran", "strided", "reversed", ">f4", ">i2", "read-only", "memmap", "float16",
                                    "bool", "int64", "list"])
def test_any_array_layout_gives_the_model_of_its_values_and_is_left_as_it_was(layout, tmp_path):
    """The model of every layout and type equals that of the same values as a C-ordered float64 array, and the
    caller's array is unchanged (it is converted to float32 once, docs/coordinates.md §1)."""
    values = np.random.default_rng(2).random((12, 7, 16))
    data = {"fortran": lambda: np.asfortranarray(values[:6]), "strided": lambda: values[::2, :, ::2],
            "reversed": lambda: values[::-1], ">f4": lambda: values[:6].astype(">f4"),
            ">i2": lambda: (values[:6] * 1000).astype(">i2"), "read-only": lambda: _read_only(values[:6]),
            "memmap": lambda: _memmap(values[:6], tmp_path), "float16": lambda: values[:6].astype(np.float16),
            "bool": lambda: values[:6] > 0.5, "int64": lambda: (values[:6] * 2**40).astype(np.int64),
            "list": lambda: values[:6].tolist()}[layout]()
    before = np.array(data, copy=True)
    expected = _coefficients(np.ascontiguousarray(np.asarray(data, dtype=np.float64)))
    np.testing.assert_array_equal(_coefficients(data), expected)
    np.testing.assert_array_equal(np.asarray(data), before)


def _read_only(a):
    a = a.copy()
    a.flags.writeable = False
    return a


def _memmap(a, folder):
    np.save(folder / "v.npy", a.astype(np.float32))
    return np.load(folder / "v.npy", mmap_mode="r")


_VOLUME = np.ones((4, 5, 6))
WRONG_ARGUMENTS = {  # each was taken, silently, as another value (or raised a TypeError of numpy's) before api22
    "interpolate='False'": (lambda wv: clwave.WaveletVolume.from_volume(clwave.Volume(_VOLUME), levels=1,
                                                                        interpolate="False"), r"interpolate='False'"),
    "absorption=None": (lambda wv: clwave.raytrace(wv, CAMERAS[0], absorption=None), r"absorption=None"),
    "perspective='no'": (lambda wv: clwave.Camera(perspective="no"), r"perspective='no'"),
    "size=True": (lambda wv: clwave.Camera(size=True), r"image size True"),
    "size=(True, 3)": (lambda wv: clwave.Camera(size=(True, 3)), r"image size \(True, 3\)"),
    "azimuth=True": (lambda wv: clwave.Camera(azimuth=True), r"azimuth must be one number"),
    "tolerance=True": (lambda wv: clwave.raytrace(wv, CAMERAS[0], tolerance=True), r"tolerance must be one number"),
    "keep=True": (lambda wv: wv.threshold(keep=True), r"keep must be one number"),
    "keep=[0.5]": (lambda wv: wv.threshold(keep=np.array([0.5])), r"keep must be one number"),
    "spacing='0.5'": (lambda wv: clwave.Volume(_VOLUME, spacing="0.5"), r"spacing='0.5' must be one number or three"),
    "spacing=True": (lambda wv: clwave.Volume(_VOLUME, spacing=True), r"spacing=True must be one number or three"),
    "origin=(1, 2)": (lambda wv: clwave.Volume(_VOLUME, origin=(1, 2)), r"origin=\(1, 2\) must be one number or three"),
    "pixel='1'": (lambda wv: clwave.ConeBeam(100, 150, 8, pixel="1"), r"pixel='1' must be a positive detector spacing"),
    "target=('1', '2', '3')": (lambda wv: clwave.Camera(target=("1", "2", "3")), r"target=\('1', .* must be three"),
    "coarse=[0.1]": (lambda wv: clwave.splat(wv, CAMERAS[0], coarse=[0.1]), r"coarse must be one number"),
    "omega_s=array": (lambda wv: clwave.splat(wv, CAMERAS[0], omega_s=np.array([14.0])), r"omega_s must be one"),
    "sampling=['fft']": (lambda wv: clwave.splat(wv, CAMERAS[0], sampling=["fft"]), r"sampling must be one of"),
    "field=['wavelet']": (lambda wv: clwave.raytrace(wv, CAMERAS[0], field=["wavelet"]), r"field must be one of"),
    "budget='1'": (lambda wv: next(clwave.progressive(wv, CAMERAS[0], budget="1")), r"budget must be a number"),
    "budget=[1, 2]": (lambda wv: next(clwave.progressive(wv, CAMERAS[0], budget=[1, 2], method="raytrace")),
                      r"budget must be one number"),
}


@pytest.mark.parametrize("case", sorted(WRONG_ARGUMENTS))
def test_a_wrong_argument_is_one_line_naming_it(rgba_model, case):
    call, named = WRONG_ARGUMENTS[case]
    with pytest.raises(clwave.InputError, match=named) as caught:
        call(rgba_model)
    assert "\n" not in str(caught.value)


def test_numpy_scalars_are_numbers(rgba_model):
    """np.float32(0.5) where a float goes gives what the float gives (coarse= refused NumPy's float32 before
    api22); a 0-d array too."""
    camera = clwave.Camera(np.float32(30), np.float64(20), size=np.int64(40), extent=np.array(30.0))
    plain = clwave.Camera(30, 20, size=40, extent=30.0)
    expected = clwave.SplatRenderer(rgba_model, coarse=0.25).render(plain).image
    np.testing.assert_array_equal(clwave.SplatRenderer(rgba_model, coarse=np.float32(0.25)).render(camera).image,
                                  expected)
    assert clwave.Volume(_VOLUME, spacing=np.float32(0.5), origin=np.zeros(3)).spacing == (0.5, 0.5, 0.5)


def test_a_returned_image_is_the_callers_and_an_abandoned_refinement_leaves_nothing(rgba_model):
    """Writing into a returned image, or leaving a progressive generator after its first frame, changes no later
    image: the next render is the one a fresh renderer gives."""
    splatter, tracer = clwave.SplatRenderer(rgba_model), clwave.RayTracer(rgba_model, lod=True)
    fresh_splat = clwave.SplatRenderer(rgba_model).render(CAMERAS[0]).image
    fresh_trace = clwave.RayTracer(rgba_model, lod=True).render(CAMERAS[0], tolerance=1e-2).image
    splatter.render(CAMERAS[0]).image[:] = 7
    splatter.render_many(CAMERAS[:1])[:] = 7
    frames = clwave.progressive(rgba_model, CAMERAS[0], steps=4, renderer=splatter)
    next(frames).image[:] = 7
    frames.close()
    tracer.render(CAMERAS[0], tolerance=1e-2).image[:] = 7
    refining = tracer.refine(CAMERAS[0], tolerance=1e-2)
    next(refining).image[:] = 7
    refining.close()
    np.testing.assert_array_equal(splatter.render(CAMERAS[0]).image, fresh_splat)
    np.testing.assert_array_equal(tracer.render(CAMERAS[0], tolerance=1e-2).image, fresh_trace)
