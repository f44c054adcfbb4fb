"""Phong's local illumination for the ray tracer (paper eq. 4; docs/raytracing.md §5): its weights, and the
directions of the lights."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..device.constants import MAX_LIGHTS
from ..errors import InputError, finite_number
from ..model.geometry import view_frame


@dataclass(frozen=True)
class Phong:
    """Phong local illumination (paper eq. 4): ambient, diffuse, specular weights and exponent.

    The ambient and diffuse terms scale the classified emission q; the specular term adds
    white light in proportion to the opacity, so highlights sit on surfaces.
    """

    ambient: float = 0.3
    diffuse: float = 0.7
    specular: float = 0.3
    shininess: float = 20.0

    def __post_init__(self):
        for name in ("ambient", "diffuse", "specular", "shininess"):
            value = finite_number(getattr(self, name), name)
            if value < 0:
                raise InputError(f"Phong {name}={value} must not be negative")


def light_direction(azimuth, elevation) -> np.ndarray:
    """Unit vector towards a light at (azimuth, elevation) degrees, as paper eq. 31's n."""
    return view_frame(finite_number(azimuth, "light azimuth"), finite_number(elevation, "light elevation"))[0]


def light_directions(lights, headlight) -> list:
    """The unit vectors towards ``lights`` (a list of (azimuth, elevation) pairs in degrees, ``[]`` for none, None
    for a ``headlight`` alone, the view's direction), or one InputError naming that form."""
    if lights is None:
        return [headlight]
    form = "a list of (azimuth, elevation) pairs in degrees, [(az, el), ...], or [] for none"
    if isinstance(lights, (str, bytes)) or not np.iterable(lights):
        raise InputError(f"lights={lights!r} must be {form}")
    lights = list(lights)
    for i, light in enumerate(lights):
        if isinstance(light, (str, bytes)) or not np.iterable(light) or len(light) != 2:
            one = f"; one light is [{tuple(lights)!r}]" if len(lights) == 2 and not np.iterable(light) else ""
            raise InputError(f"lights[{i}]={light!r} is not an (azimuth, elevation) pair: lights must be {form}{one}")
    if len(lights) > MAX_LIGHTS:
        raise InputError(f"at most {MAX_LIGHTS} lights, got {len(lights)}")
    return [light_direction(*light) for light in lights]
