"""clwave: wavelet-domain volume rendering in Python and OpenCL.

See README.md for the quick start; coordinates follow CONVENTIONS.md (host arrays
(z, y, x[, c]), spacing (dz, dy, dx), world points (x, y, z)).
"""

from .errors import (ClwaveError, DeviceMemoryError, DeviceNotFoundError, FileFormatError,
                     InputError, KernelBuildError, OutputExistsError)
from .volume import Volume
from .device import ComputeContext, list_devices, select_device
from .loaders import load
from .phantoms import phantom
from .transfer import TransferFunction
from .wavelet import WaveletVolume
from .camera import Camera
from .result import RenderResult
from .splat import SplatRenderer, splat
from .progressive import progressive
from .raytrace import Phong, RayTracer, raytrace

__version__ = "0.1.0"

__all__ = [
    "ClwaveError", "DeviceMemoryError", "DeviceNotFoundError", "FileFormatError", "InputError",
    "KernelBuildError", "OutputExistsError", "Volume", "ComputeContext", "list_devices",
    "select_device", "load", "phantom", "TransferFunction", "WaveletVolume", "Camera", "RenderResult",
    "SplatRenderer", "splat", "progressive", "Phong", "RayTracer", "raytrace", "__version__",
]
