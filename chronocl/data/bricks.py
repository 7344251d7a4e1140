"""Z-slabs of a volume, with the one-voxel halo that gradients need.

Integration is independent per z-slab: a slab [z0, z1) is read as
[r0, r1) = [z0 - halo, z1 + halo] clipped to the volume, integrated, and its
halo rows cropped. The engine streams these in xytz order (slab, W, Y, X).
"""

from __future__ import annotations

from dataclasses import dataclass

from chronocl.core.errors import InvalidParameterError


@dataclass(frozen=True)
class Slab:
    z0: int  # first output row
    z1: int  # one past the last output row
    r0: int  # first row read (z0 minus halo, clipped)
    r1: int  # one past the last row read

    @property
    def crop(self) -> slice:
        """Rows of the read block that belong to the output."""
        return slice(self.z0 - self.r0, self.z1 - self.r0)


def slabs(nz: int, slab: int, halo: int = 0) -> list[Slab]:
    """Cover [0, nz) with slabs of `slab` rows (the last may be shorter)."""
    if slab < 1:
        raise InvalidParameterError(f"slab size must be at least 1 row, got {slab}")
    if halo < 0:
        raise InvalidParameterError(f"halo must be >= 0, got {halo}")
    out = []
    for z0 in range(0, nz, slab):
        z1 = min(z0 + slab, nz)
        out.append(Slab(z0, z1, max(0, z0 - halo), min(nz, z1 + halo)))
    return out
