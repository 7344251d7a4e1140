"""VTK peer for ``bench/integrate.py``: per-voxel maximum over time with ``vtkTemporalStatistics``.

This is what a ParaView user runs for "max over time": a temporal source feeding
``vtkTemporalStatistics`` (only ``ComputeMaximum`` on).  The source is a small
``VTKPythonAlgorithmBase`` that announces ``T`` time steps and, when the pipeline asks for one,
wraps the matching ``steps[t]`` slab of the caller's ``(T, Z, Y, X)`` numpy array as a
``vtkImageData`` point array without copying (``numpy_to_vtk(..., deep=False)``).  A C-order
ravel of a ``(Z, Y, X)`` slab is VTK's x-fastest point order for the extent
``(0..X-1, 0..Y-1, 0..Z-1)``, so no transpose is needed either way.

``vtkTemporalStatistics`` drives the time loop itself: its ``RequestUpdateExtent`` asks the
source for one time step at a time and its ``RequestData`` sets ``CONTINUE_EXECUTING`` until all
announced steps have been accumulated (since VTK 9.4 through ``vtkTemporalAlgorithm``).
``run_max`` marks the source modified before each ``Update`` so that every call redoes the full
T-step reduction instead of returning the cached output.

Usage::

    pipe = make_pipeline(steps)  # steps: (T, Z, Y, X) float32/uint8, C-contiguous
    vmax = run_max(pipe)  # (Z, Y, X), equals steps.max(axis=0)
"""

from __future__ import annotations

from typing import Any

import numpy as np

ARRAY_NAME = "scalars"


def vtk_available() -> bool:
    """Whether the VTK modules this peer needs can be imported."""
    try:
        from vtkmodules.util import numpy_support
        from vtkmodules.util.vtkAlgorithm import VTKPythonAlgorithmBase
        from vtkmodules.vtkFiltersGeneral import vtkTemporalStatistics
    except ImportError:
        return False
    return all(
        m is not None for m in (numpy_support, VTKPythonAlgorithmBase, vtkTemporalStatistics)
    )


def vtk_version() -> str | None:
    """The VTK version string, or ``None`` when VTK is not installed."""
    try:
        from vtkmodules.vtkCommonCore import vtkVersion
    except ImportError:
        return None
    return str(vtkVersion.GetVTKVersion())


def _make_source_class() -> type:
    """Build the source class lazily so that importing this module never needs VTK."""
    from vtkmodules.util import numpy_support
    from vtkmodules.util.vtkAlgorithm import VTKPythonAlgorithmBase
    from vtkmodules.vtkCommonDataModel import vtkImageData
    from vtkmodules.vtkCommonExecutionModel import vtkStreamingDemandDrivenPipeline as SDDP

    class NumpyTimeSource(VTKPythonAlgorithmBase):
        """No-input source serving ``steps[t]`` as a zero-copy ``vtkImageData`` per time step."""

        def __init__(self, steps: np.ndarray) -> None:
            super().__init__(nInputPorts=0, nOutputPorts=1, outputType="vtkImageData")
            self._steps = steps  # keeps the wrapped memory alive
            t, z, y, x = steps.shape
            self._times = np.arange(t, dtype=np.float64)
            self._extent = (0, x - 1, 0, y - 1, 0, z - 1)

        def RequestInformation(self, request, inInfo, outInfo):
            info = outInfo.GetInformationObject(0)
            info.Set(SDDP.WHOLE_EXTENT(), *self._extent)
            info.Set(SDDP.TIME_STEPS(), self._times, len(self._times))
            info.Set(SDDP.TIME_RANGE(), [self._times[0], self._times[-1]], 2)
            return 1

        def RequestData(self, request, inInfo, outInfo):
            info = outInfo.GetInformationObject(0)
            t = 0
            if info.Has(SDDP.UPDATE_TIME_STEP()):
                # Nearest announced step at or below the requested time (times are 0..T-1).
                want = info.Get(SDDP.UPDATE_TIME_STEP())
                t = int(np.clip(np.searchsorted(self._times, want, side="right") - 1, 0, None))
            flat = self._steps[t].reshape(-1)  # a view: steps is C-contiguous
            arr = numpy_support.numpy_to_vtk(flat, deep=False)
            arr.SetName(ARRAY_NAME)
            out = vtkImageData.GetData(outInfo)
            out.SetExtent(*self._extent)
            out.GetPointData().SetScalars(arr)
            out.GetInformation().Set(out.DATA_TIME_STEP(), float(self._times[t]))
            return 1

    return NumpyTimeSource


class VtkMaxPipeline:
    """Source and filter of one ``vtkTemporalStatistics`` max pipeline, plus the served data."""

    __slots__ = ("source", "stats", "steps")

    def __init__(self, steps: np.ndarray, source: Any, stats: Any) -> None:
        self.steps = steps
        self.source = source
        self.stats = stats


def make_pipeline(steps: np.ndarray) -> VtkMaxPipeline:
    """Wire a zero-copy time-step source into ``vtkTemporalStatistics`` (maximum only).

    ``steps`` is a ``(T, Z, Y, X)`` C-contiguous array (float32 or uint8, or any dtype that
    ``numpy_to_vtk`` maps); it is referenced, not copied, and must not change while in use.
    """
    from vtkmodules.vtkFiltersGeneral import vtkTemporalStatistics

    steps = np.asarray(steps)
    if steps.ndim != 4:
        raise ValueError(f"steps must be (T, Z, Y, X), got shape {steps.shape}")
    if steps.shape[0] < 1:
        raise ValueError("steps needs at least one time step")
    if not steps.flags.c_contiguous:
        raise ValueError("steps must be C-contiguous (the source wraps it without copying)")

    source = _make_source_class()(steps)
    stats = vtkTemporalStatistics()
    stats.ComputeAverageOff()
    stats.ComputeMinimumOff()
    stats.ComputeStandardDeviationOff()
    stats.ComputeMaximumOn()
    stats.SetInputConnection(source.GetOutputPort())
    return VtkMaxPipeline(steps=steps, source=source, stats=stats)


def run_max(pipeline: VtkMaxPipeline) -> np.ndarray:
    """Execute the pipeline once over all T steps; return the ``(Z, Y, X)`` maximum.

    The source is marked modified first, so every call re-executes the whole temporal loop.
    The result wraps the filter's output array without copying; it keeps that array alive, and
    the filter builds a new one on the next call, so earlier results stay valid.
    """
    from vtkmodules.util import numpy_support

    pipeline.source.Modified()
    pipeline.stats.Update()
    out = pipeline.stats.GetOutputDataObject(0)
    arr = out.GetPointData().GetArray(f"{ARRAY_NAME}_maximum")
    if arr is None:
        raise RuntimeError("vtkTemporalStatistics produced no maximum array")
    _, z, y, x = pipeline.steps.shape
    return numpy_support.vtk_to_numpy(arr).reshape(z, y, x)
