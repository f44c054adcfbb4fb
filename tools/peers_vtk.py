"""VTK's CPU ray caster (``vtkFixedPointVolumeRayCastMapper``) set up as ``tools/compare_peers.py`` measures it
(docs/peers.md §2): offscreen through EGL, ``Render()`` alone timed, the read-back apart.

Beside the defaults (the voxels, trilinear, one sample a voxel length, 8-bit output) a scene takes what a user who
wants a more accurate image from this mapper can change: a smaller sample distance; nearest-voxel interpolation
(the mapper offers nearest and linear only: cubic is the GPU mapper's); a finer volume, the cubic B-spline of
the voxels resampled by ``vtkImageReslice`` with ``vtkImageBSplineInterpolator`` (the voxels as its
coefficients: clwave's approximating model, docs/coordinates.md §1, zero outside); and a final colour window,
which maps a narrower range of the mapper's 15-bit image onto the 8 bits it returns (``SetFinalColorWindow``).
"""

from __future__ import annotations

import math
import os
import time

import numpy as np

import clwave

#: voxels of zeros around the volume before it is resampled: the cubic B-spline's support reaches 2 voxels out
PAD = 2


class VtkScene:
    """One volume, mapper, property and offscreen window; ``render(view)`` -> (seconds, readback seconds, image).

    ``blend``: "additive" (a linear opacity ramp, a speed reference) or "composite" (shaded emission-absorption
    under ``tf``, its opacity per world unit turned into VTK's per unit distance, 1 - exp(-alpha), and the Phong
    weights and headlight of ``clwave.Phong``).  ``resample`` > 1 renders the volume's cubic B-spline sampled
    ``resample`` times finer along each axis; ``window`` is the final colour window (the image is scaled back)."""

    def __init__(self, vol, size, blend="composite", tf=None, sample_distance=1.0, interpolation="linear",
                 resample=1, window=1.0):
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
        import vtkmodules.vtkRenderingOpenGL2  # noqa: F401  (registers the OpenGL render window)
        import vtkmodules.vtkRenderingVolumeOpenGL2  # noqa: F401  (the ray caster's display helper)
        from vtkmodules.vtkCommonDataModel import vtkPiecewiseFunction
        from vtkmodules.vtkRenderingCore import (vtkColorTransferFunction, vtkLight, vtkRenderer, vtkRenderWindow,
                                                 vtkVolume, vtkVolumeProperty, vtkWindowToImageFilter)
        from vtkmodules.vtkRenderingVolume import vtkFixedPointVolumeRayCastMapper

        self.mapper = vtkFixedPointVolumeRayCastMapper()
        self.mapper.SetInputData(_image(vol, resample))
        self.mapper.AutoAdjustSampleDistancesOff()
        self.set(sample_distance, window)
        opacity, colour, prop = vtkPiecewiseFunction(), vtkColorTransferFunction(), vtkVolumeProperty()
        if blend == "additive":
            top = float(vol.data.max())
            self.mapper.SetBlendModeToAdditive()
            opacity.AddPoint(0.0, 0.0)
            opacity.AddPoint(top, 0.05)
            colour.AddRGBPoint(0.0, 1.0, 1.0, 1.0)
            colour.AddRGBPoint(top, 1.0, 1.0, 1.0)
        else:
            self.mapper.SetBlendModeToComposite()
            lo, hi = tf.window
            for value, r, g, b, alpha in tf.points:
                x = lo + value * (hi - lo)
                colour.AddRGBPoint(x, r, g, b)
                opacity.AddPoint(x, 1.0 - math.exp(-alpha))      # absorbed over one world unit
            prop.SetScalarOpacityUnitDistance(1.0)
            phong = clwave.Phong()
            prop.ShadeOn()
            prop.SetAmbient(phong.ambient)
            prop.SetDiffuse(phong.diffuse)
            prop.SetSpecular(phong.specular)
            prop.SetSpecularPower(phong.shininess)
        prop.SetScalarOpacity(opacity)
        prop.SetColor(colour)
        if interpolation == "linear":
            prop.SetInterpolationTypeToLinear()
        elif interpolation == "nearest":
            prop.SetInterpolationTypeToNearest()
        else:
            raise ValueError(f"interpolation {interpolation!r}: VTK's fixed-point ray caster has 'linear' and "
                             f"'nearest' (cubic is its GPU mapper's)")
        volume = vtkVolume()
        volume.SetMapper(self.mapper)
        volume.SetProperty(prop)
        self.renderer = vtkRenderer()
        self.renderer.AddVolume(volume)
        if blend == "composite":  # clwave's light: one headlight, one-sided, ambient term = ka (VTK's default: 0)
            light = vtkLight()
            light.SetLightTypeToHeadlight()
            light.SetAmbientColor(1.0, 1.0, 1.0)
            self.renderer.AddLight(light)
            self.renderer.TwoSidedLightingOff()
        self.window = vtkRenderWindow()
        self.window.SetOffScreenRendering(1)
        self.window.AddRenderer(self.renderer)
        self.H, self.W = clwave.Camera(size=size).size
        self.window.SetSize(self.W, self.H)
        self.grab = vtkWindowToImageFilter()
        self.grab.SetInput(self.window)
        self.grab.ReadFrontBufferOff()
        self.grab.ShouldRerenderOff()                          # read what Render() drew, without drawing again

    def set(self, sample_distance, window=1.0):
        """The sample distance (world units) and the final colour window: [0, window] of the 15-bit image onto the
        8 bits it returns (``render`` scales the image back)."""
        self.mapper.SetSampleDistance(sample_distance)
        self.mapper.SetFinalColorWindow(window)
        self.mapper.SetFinalColorLevel(window / 2.0)
        self.window_scale = window

    def render(self, view) -> tuple:
        """``Render()`` of a clwave ``View`` (orthographic): its seconds, the read-back's, and the RGB image in
        [0, 1] (float32, rows top down, scaled back from the final colour window)."""
        from vtkmodules.util.numpy_support import vtk_to_numpy

        eye = self.renderer.GetActiveCamera()
        eye.ParallelProjectionOn()
        eye.SetFocalPoint(*view.target)
        eye.SetPosition(*(view.target + 2.0 * self.W * view.pixel * view.n))
        eye.SetViewUp(*view.v)
        eye.SetParallelScale(self.H * view.pixel / 2.0)
        self.renderer.ResetCameraClippingRange()
        t = time.perf_counter()
        self.window.Render()
        seconds = time.perf_counter() - t
        t = time.perf_counter()
        self.grab.Modified()
        self.grab.Update()
        rgb = vtk_to_numpy(self.grab.GetOutput().GetPointData().GetScalars()).reshape(self.H, self.W, -1)
        readback = time.perf_counter() - t
        return seconds, readback, rgb[::-1, :, :3].astype(np.float32) * (self.window_scale / 255.0)


def _image(vol, resample):
    """The ``vtkImageData`` of the volume (world positions as clwave's, docs/coordinates.md §1), or, for
    ``resample`` > 1, of its cubic B-spline (the voxels as coefficients, zero outside) sampled ``resample`` times
    finer over the model's support, by ``vtkImageReslice`` with ``vtkImageBSplineInterpolator``."""
    from vtkmodules.util.numpy_support import numpy_to_vtk
    from vtkmodules.vtkCommonDataModel import vtkImageData

    data = vol.data if resample == 1 else np.pad(vol.data, PAD)
    nz, ny, nx = data.shape
    spacing = np.array(vol.spacing[::-1], float)
    image = vtkImageData()
    image.SetDimensions(nx, ny, nz)
    image.SetSpacing(*spacing)
    image.SetOrigin(*(np.array(vol.origin) - (np.array([nx, ny, nz]) - 1) / 2.0 * spacing))
    image.GetPointData().SetScalars(numpy_to_vtk(data.ravel(), deep=True))
    if resample == 1:
        return image
    from vtkmodules.vtkImagingCore import vtkImageBSplineInterpolator, vtkImageReslice

    spline = vtkImageBSplineInterpolator()
    spline.SetSplineDegree(3)
    reslice = vtkImageReslice()
    reslice.SetInputData(image)
    reslice.SetInterpolator(spline)
    reslice.SetOutputSpacing(*(spacing / resample))
    reslice.SetOutputOrigin(*image.GetOrigin())
    reslice.SetOutputExtent(0, (nx - 1) * resample, 0, (ny - 1) * resample, 0, (nz - 1) * resample)
    reslice.Update()
    return reslice.GetOutput()
