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


@pytest.fixture(scope="module")
def rgba_model():
    vol = clwave.phantom("hydrogen", n=20)
    rgba = clwave.TransferFunction.preset("hydrogen").classify(vol)
    return clwave.WaveletVolume.from_volume(rgba, levels=2).threshold(keep=0.2)


CAMERAS = (clwave.Camera(30, 20, size=40), clwave.Camera(100, -10, size=(24, 36)))


def _in_two_threads(render):
    """Each of two threads renders both cameras three times, alternately; the images, per camera."""
    images = {0: [], 1: []}

    def work(first):
        for k in range(6):
            which = (first + k) % 2
            images[which].append(render(CAMERAS[which]))

    threads = [threading.Thread(target=work, args=(first,)) for first in (0, 1)]
    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-5)  # the threads take turns often: what a race there is shows in a few views
    try:
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    finally:
        sys.setswitchinterval(interval)
    return images


@pytest.mark.parametrize("kind", ["splat", "raytrace"])
def test_one_renderer_shared_by_two_threads_renders_each_view_as_alone(rgba_model, kind):
    """Two threads rendering through one renderer at once: each image is bit for bit the one the same renderer
    gives a view alone (a SplatRenderer's views shared its device buffers: one of eight images came out wrong by
    up to 4e32 before api22; renders now take their turn, threads.one_at_a_time)."""
    if kind == "splat":
        renderer = clwave.SplatRenderer(rgba_model)
        render = lambda camera: renderer.render(camera).image  # noqa: E731
    else:
        renderer = clwave.RayTracer(rgba_model)
        render = lambda camera: renderer.render(camera, tolerance=1e-2).image  # noqa: E731
    alone = [render(camera) for camera in CAMERAS]
    images = _in_two_threads(render)
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
