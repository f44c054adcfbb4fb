"""clwave: wavelet-domain volume rendering in Python and OpenCL.

See README.md for the quick start; coordinates follow docs/coordinates.md (host arrays
(z, y, x[, c]), spacing (dz, dy, dx), world points (x, y, z)).
"""

from .errors import (ClwaveError, ClwaveWarning, DeviceMemoryError, DeviceNotFoundError, FileFormatError,
                     InputError, KernelBuildError, OutputError, OutputExistsError, WorkerLostError)
from .model.volume import Volume
from .device.context import ComputeContext, list_devices, select_device
from .device.memory import HostMemoryError
from .io.loaders import load
from .io.phantoms import phantom
from .model.transfer import TransferFunction
from .model.wavelet import WaveletVolume
from .model.camera import Camera
from .model.geometry import named_view
from .model.clip import Clip
from .model.conebeam import ConeBeam, transmitted
from .io.result import RenderResult
from .io.progress import show_progress
from .splat.renderer import SplatRenderer, splat
from .progressive import progressive
from .turntable import Turntable, turntable
from .raytrace.shading import Phong
from .raytrace.tracer import RayTracer, raytrace
from .raytrace.lod import Detail
from .model.chunked import ChunkedWaveletVolume
from .io import clw as _clw  # noqa: F401  (WaveletVolume.save and .open: the model does not import its file format)
from .view import Viewer, view

__version__ = "0.1.0"

__all__ = [
    "ClwaveError", "ClwaveWarning", "DeviceMemoryError", "DeviceNotFoundError", "FileFormatError", "InputError",
    "KernelBuildError", "OutputError", "OutputExistsError", "HostMemoryError", "WorkerLostError", "Volume",
    "ComputeContext",
    "list_devices",
    "select_device", "load", "phantom", "TransferFunction", "WaveletVolume", "Camera", "named_view", "Clip", "ConeBeam",
    "transmitted",
    "RenderResult",
    "SplatRenderer", "splat", "progressive", "Turntable", "turntable", "Phong", "RayTracer", "raytrace", "__version__",
    "Detail",
    "ChunkedWaveletVolume",
    "Viewer", "view", "show_progress",
]
