"""A ray tracer's set-up given up from another thread (``RayTracer(..., abandon=)``, clwave/threads.py,
docs/raytracing.md §8): once the event is set, each step of the set-up stops at its next checkpoint (a band of the
plan, a brick row of the content's windows, a slab of the expansion, a brick layer of the mixed bricks' pieces, a
band of slots of a scalar model's ranges, a chunk of its pool's packing, a band of the wavelet field) with
``Abandoned``, whether or not the model has a content mask.  Counted in units of work run after the event, not in
wall time.  A tracer set up with an event never set is bit for bit the one set up without."""

import threading

import numpy as np
import pytest

import clwave
from clwave.raytrace import bricks, classified, lod, pieces, wavelet_field
from clwave.raytrace.tracer import RayTracer
from clwave.threads import Abandoned
from test_bricks import mixed_model, smooth_rgba

pytestmark = pytest.mark.opencl


def hydrogen(interpolate):
    """A scalar model: ``interpolate=True`` has no content mask, the default one."""
    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", n=32), levels=2, interpolate=interpolate)
    return wv.threshold(keep=0.2)


def rgba(wavelet="cubic"):
    """An RGBA model with a content mask and an empty corner; mixed orders: two channel groups."""
    return clwave.WaveletVolume.from_volume(smooth_rgba(n=32, empty_corner=True), wavelet=wavelet,
                                            levels=2).threshold(keep=0.2)


MIXED = ["cubic", "cubic", "cubic", "linear"]


# (module, the function one unit of the step calls, the model, the tracer's options, calls one unit makes at most)
STEPS = {
    "plan's bands, no mask": (bricks, "_reach", lambda: hydrogen(True), dict(lod=True), 1),
    "plan's brick rows": (lod, "occupancy", lambda: rgba(), {}, 1),
    "slabs, no mask (shaded)": (bricks, "_expand_slab", lambda: hydrogen(True), dict(lod=True), 1),
    "slabs, X-ray (mask dropped)": (bricks, "_expand_slab", lambda: hydrogen(False), dict(content_clamp=False), 1),
    "slabs, two groups": (bricks, "_expand_slab", lambda: rgba(MIXED), dict(lod=True), 2),
    "mixed bricks' layers": (pieces, "content_cells", mixed_model, {}, 2),  # two layers of them
    "scalar ranges' bands, no mask": (classified, "_RANGE", lambda: hydrogen(True), dict(lod=True), 1),
    "scalar pool's chunks, no mask": (classified, "_pack_slots", lambda: hydrogen(True), dict(lod=True), 1),
    "wavelet field's bands": (wavelet_field, "band_lattice", lambda: hydrogen(True), dict(field="wavelet"), 1),
}


@pytest.mark.parametrize("step", STEPS)
def test_a_set_up_given_up_stops_at_the_next_checkpoint_of_its_step(step, monkeypatch):
    """The event set inside the step's first unit of work: the unit finishes (each slab its groups), no other
    starts, and the set-up raises ``Abandoned``."""
    module, name, make, options, per_unit = STEPS[step]
    wv, abandon, calls = make(), threading.Event(), []
    assert (wv.content_mask is None) == (wv.interpolate is True)  # an interpolating model has no mask
    work = getattr(module, name)

    def counted(*args, **kwargs):
        calls.append(abandon.is_set())
        abandon.set()  # as a viewer closing, from its thread
        return work(*args, **kwargs)

    monkeypatch.setattr(module, name, counted)
    with pytest.raises(Abandoned, match="given up"):
        RayTracer(wv, abandon=abandon, **options)
    assert calls and calls[0] is False, "the step never ran"
    assert len(calls) <= per_unit, f"{len(calls) - 1} calls after the event (one unit makes {per_unit})"


def test_an_event_set_before_the_set_up_stops_it_before_any_expansion(monkeypatch):
    """Given up before it starts (a viewer closed at once): no slab is expanded, no scratch file nor pool made."""
    slabs = []
    monkeypatch.setattr(bricks, "_expand_slab", lambda *args: slabs.append(1))
    abandon = threading.Event()
    abandon.set()
    with pytest.raises(Abandoned):
        RayTracer(hydrogen(True), abandon=abandon, lod=True)
    assert not slabs


GREY = dict(transfer_function=clwave.TransferFunction.preset("grey"))


@pytest.mark.parametrize("make, options, view", [(lambda: hydrogen(True), dict(lod=True), GREY),
                                                 (lambda: hydrogen(False), dict(content_clamp=False),
                                                  dict(absorption=False)),
                                                 (lambda: rgba(MIXED), dict(lod=True), {})],
                         ids=["interpolating, shaded", "X-ray", "RGBA, two groups"])
def test_a_tracer_with_an_event_never_set_is_the_tracer_without(make, options, view):
    """The checkpoints only read the event: the pool (a scalar model's packed), the bounds and a render are bit for
    bit the same."""
    wv, camera = make(), clwave.Camera(30, 20, size=24)
    plain, watched = RayTracer(wv, **options), RayTracer(wv, abandon=threading.Event(), **options)
    assert np.array_equal(plain.bricks.pool.get(), watched.bricks.pool.get())
    assert np.array_equal(plain.bricks.bounds, watched.bricks.bounds)
    image = plain.render(camera, **view).image
    assert np.array_equal(image, watched.render(camera, **view).image) and image.any()


def test_abandon_must_be_an_event():
    wv = clwave.WaveletVolume.from_volume(clwave.phantom("hydrogen", 16), levels=1)
    with pytest.raises(clwave.InputError, match="threading.Event"):
        clwave.RayTracer(wv, abandon=True)
