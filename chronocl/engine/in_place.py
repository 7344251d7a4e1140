"""Bricks read where their steps lie (`chronocl.data.bricks.SlotBrick`): how their rows are cut
into chunks that one device buffer each can wrap, and whether a chunk's loads are aligned.

On a CPU device the engine wraps host memory in place (CL_MEM_USE_HOST_PTR) instead of copying
a brick. A brick whose steps lie apart spans more memory than its own bytes, and a buffer may
hold at most the device's largest allocation: the rows then go in chunks, each wrapped on its
own, with the halo rows gradients need.
"""

from __future__ import annotations

import numpy as np

from chronocl.core.memory import is_aligned
from chronocl.data.bricks import SlotBrick
from chronocl.engine.transfer import Chunk, chunks_of

ALIGN_SLACK = 64  # bytes a chunk's buffer may start early to begin on an aligned address


def slot_chunks(brick: SlotBrick, crop: slice, halo: int, limit: int) -> list[Chunk] | None:
    """The chunks of brick rows `crop` whose spans each fit a buffer of `limit` bytes (one
    chunk where the whole brick does), or None where not even one row and its halo fits."""
    if brick.block.nbytes <= limit:
        return [Chunk(crop.start, crop.stop, 0, brick.shape[0])]
    row = brick.zstride * brick.dtype.itemsize  # the span grows by this per row
    fixed = brick.rows(0, 1).block.nbytes + ALIGN_SLACK
    if fixed + 2 * halo * row > limit:
        return None
    return chunks_of(brick.shape[0], crop, halo, row, limit - fixed + row)


def aligned_part(part: SlotBrick, lanes: int) -> bool:
    """Whether every step of a chunk's brick starts on a `lanes`-element boundary of an
    aligned buffer (the kernels' vector loads then need no fix-up)."""
    return is_aligned(part.block) and not (np.asarray(part.offsets) % lanes).any()
