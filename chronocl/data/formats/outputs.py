"""Where a chronovolume can be saved, chosen by the path's suffix.

``.zarr``: chronocl's own store (reloads with `Chronovolume.load`); ``.ome.zarr``: OME-Zarr
(NGFF 0.4) image with RGBA channels and the t_index, which napari opens; ``.vti``: VTK XML image
data with `rgba` and `t_index` point arrays, which ParaView opens.
"""

from __future__ import annotations

import os
from pathlib import Path

from chronocl.core.errors import InvalidParameterError
from chronocl.data.chronovolume import Chronovolume

KINDS = {".ome.zarr": "OME-Zarr (napari)", ".zarr": "chronocl zarr", ".vti": "VTK (ParaView)"}


def output_kind(path: str | os.PathLike) -> str:
    """The suffix that decides the format; raises for anything else (call before the work)."""
    name = str(path).lower().rstrip("/")
    for suffix in KINDS:
        if name.endswith(suffix):
            return suffix
    raise InvalidParameterError(
        f"cannot tell the chronovolume format of {str(path)!r}; end it in .zarr (chronocl), "
        ".ome.zarr (napari) or .vti (ParaView)"
    )


def save_chronovolume(cv: Chronovolume, path: str | os.PathLike, overwrite: bool = False) -> Path:
    """Save `cv` in the format its suffix names, atomically."""
    kind = output_kind(path)
    if kind == ".vti":
        from chronocl.data.formats.vti import save_chronovolume_vti

        return save_chronovolume_vti(cv, path, overwrite=overwrite)
    if kind == ".ome.zarr":
        from chronocl.data.formats.omezarr_write import save_chronovolume_omezarr

        return save_chronovolume_omezarr(cv, path, overwrite=overwrite)
    return cv.save(path, overwrite=overwrite)
