"""Camera conventions (docs/coordinates.md §2) and bad views."""

import numpy as np
import pytest

from clwave.model.camera import Camera
from clwave.errors import InputError
from clwave.model.volume import Volume


@pytest.mark.parametrize("az, el", [(0, 0), (30, 20), (-70, -15), (90, 0), (0, 90), (123.4, -56.7)])
def test_basis_is_right_handed_and_orthonormal(az, el):
    n, u, v = Camera(az, el, 8).basis()
    assert np.allclose(np.stack([n, u, v]) @ np.stack([n, u, v]).T, np.eye(3), atol=1e-15)
    assert np.allclose(np.cross(u, v), n, atol=1e-15)


def test_axis_view_is_not_mirrored():
    # camera on +x looking along -x: image right is +y, image up is +z
    n, u, v = Camera(0, 0, 8).basis()
    assert n.tolist() == [1, 0, 0] and u.tolist() == [0, 1, 0] and v.tolist() == [0, 0, 1]


def test_pixel_centres_and_default_extent():
    vol = Volume(np.zeros((4, 6, 8)), spacing=(3.0, 2.0, 1.0), origin=(1.0, 2.0, 3.0))
    view = Camera(0, 0, (10, 20)).view(vol)
    extent = np.sqrt(8 ** 2 + 12 ** 2 + 12 ** 2)
    assert view.pixel == pytest.approx(extent / 20)
    centres = view.pixel_centres()
    assert centres.shape == (10, 20, 3)
    # top-left pixel centre: target + (0.5 - W/2) p u + (H/2 - 0.5) p v
    expected = np.array([1.0, 2.0, 3.0]) + (0.5 - 10) * view.pixel * view.u + (5 - 0.5) * view.pixel * view.v
    assert np.allclose(centres[0, 0], expected)
    assert np.allclose(view.to_pixels(centres.reshape(-1, 3)).reshape(10, 20, 2)[3, 7], [7, 3])


@pytest.mark.parametrize("kwargs", [dict(azimuth=float("nan")), dict(elevation=float("inf")), dict(size=0),
                                    dict(size=(-3, 4)), dict(size=2.5), dict(size="big"), dict(extent=0),
                                    dict(target=(0, 0)), dict(fov=180)])
def test_bad_views_are_one_line_errors(kwargs):
    with pytest.raises(InputError) as err:
        Camera(**kwargs)
    assert "\n" not in str(err.value)
