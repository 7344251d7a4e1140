"""Where a chronovolume can be saved, chosen by the path's suffix among the registry's outputs.

``.zarr``: chronocl's own store (reloads with `Chronovolume.load`); ``.ome.zarr``: OME-Zarr
(NGFF 0.4) image with RGBA channels and the t_index, which napari opens; ``.vti``: VTK XML image
data with `rgba` and `t_index` point arrays, which ParaView opens.
"""

from __future__ import annotations

import os
from pathlib import Path

from chronocl.core.errors import InvalidParameterError
from chronocl.data.chronovolume import Chronovolume
from chronocl.data.formats.contract import Output
from chronocl.data.formats.registry import OUTPUTS, output_for


def output_kind(path: str | os.PathLike) -> str:
    """The suffix that decides the format; raises for anything else (call before the work)."""
    return _output(path).suffix


def save_chronovolume(cv: Chronovolume, path: str | os.PathLike, overwrite: bool = False) -> Path:
    """Save `cv` in the format its suffix names, atomically (never over its source store)."""
    output = _output(path)
    cv.check_apart_from_source(path)
    return output.save(cv, path, overwrite=overwrite)


def _output(path: str | os.PathLike) -> Output:
    output = output_for(path)
    if output is None:
        named = [f"{o.suffix} ({o.opens_in})" for o in OUTPUTS]
        raise InvalidParameterError(
            f"cannot tell the chronovolume format of {str(path)!r}; end it in "
            f"{', '.join(named[:-1])} or {named[-1]}"
        )
    return output
