"""Input files for the readers: globs expanded, every file checked, sorted naturally."""

from __future__ import annotations

import glob
import os
from collections.abc import Sequence
from pathlib import Path

from natsort import natsorted

from chronocl.core.errors import InputNotFoundError, InvalidParameterError
from chronocl.core.paths import GLOB_CHARS

NO_INPUTS = "no input files given; pass files or a glob such as 'v_*.raw'"


def expand_inputs(inputs: Sequence[str | os.PathLike]) -> list[Path]:
    """Expand globs, check every file exists, and sort naturally (step2 before step10)."""
    if not inputs:
        raise InputNotFoundError(NO_INPUTS)
    files: list[str] = []
    for item in inputs:
        text = str(item)
        if GLOB_CHARS & set(text):
            matched = glob.glob(text)
            if not matched:
                raise InputNotFoundError(f"no files match {text!r}; check the pattern and folder")
            files.extend(matched)
        elif not os.path.exists(text):
            raise InputNotFoundError(f"input file {text!r} does not exist")
        elif os.path.isdir(text):
            raise InvalidParameterError(
                f"input {text!r} is a folder; give the files inside it, e.g. '{text}/*.raw'"
            )
        else:
            files.append(text)
    return [Path(f) for f in natsorted(dict.fromkeys(files))]
