"""Features of one step: the connected components of the voxels the step shows.

A voxel is shown where its value reaches a threshold in data units (`Mask.of_threshold`), or,
given a data transfer function, where the TF's opacity at the voxel's normalised value exceeds
an opacity threshold (`Mask.of_tf`): the value normalised and the opacity looked up exactly as
the engines do it (`chronocl.core.values.normalize`, `chronocl.core.tf.lut_lerp32`), so a
feature is what a chronovolume shows of the step. Non-finite values are never shown.

The shown voxels are labelled by connected-components-3d with 6 (faces), 18 (and edges) or 26
(and corners) connectivity. A periodic axis joins its two faces: the library wraps only every
axis at once and only with 6 connectivity, so the components are labelled without wrapping and
those that touch across a periodic face are merged here, through a union-find over the pairs of
labels facing each other across it (every neighbour offset of the connectivity, the diagonal
ones included). Each feature has its size (voxels), the sum of its values (data units), its
centroid in voxel indices (z, y, x) and in world coordinates (x, y, z: origin + index x
spacing, the voxel centres), its bounding box and whether it touches the volume's boundary (a
face of a non-periodic axis longer than one voxel).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from chronocl.core.errors import InvalidParameterError
from chronocl.core.tf import DataTF, lut_lerp32
from chronocl.core.values import normalize
from chronocl.events import extra

AXES = "zyx"  # the array's axis order; every per-axis tuple here follows it unless named _xyz
CONNECTIVITIES = (6, 18, 26)
Periodic = tuple[bool, bool, bool]  # z, y, x
NOT_PERIODIC: Periodic = (False, False, False)
CHUNK = 1 << 22  # voxels masked or measured at once: the temporaries of a large step stay small


def check_connectivity(connectivity: object) -> int:
    """6, 18 or 26, else one line naming the choices."""
    if isinstance(connectivity, bool) or connectivity not in CONNECTIVITIES:
        raise InvalidParameterError(
            f"connectivity {connectivity!r} is not one of 6 (faces), 18 (faces and edges) or "
            "26 (faces, edges and corners); e.g. connectivity=26"
        )
    return int(connectivity)  # type: ignore[call-overload]


def parse_periodic(periodic: object) -> Periodic:
    """The periodic axes as (z, y, x) flags from False/None (none), True (all), or the axes'
    letters: "x", "xz", "x,y,z", "none" (or a list of letters)."""
    if periodic is None or periodic is False:
        return NOT_PERIODIC
    if periodic is True:
        return (True, True, True)
    if isinstance(periodic, str):
        text = periodic.strip().lower()
        letters = [] if text in ("", "none") else [c for c in text if c not in ", "]
    elif isinstance(periodic, Sequence) and all(isinstance(c, str) for c in periodic):
        letters = [c.strip().lower() for c in periodic]
    else:
        letters = None
    if letters is None or any(c not in AXES for c in letters) or len(set(letters)) < len(letters):
        raise InvalidParameterError(
            f"periodic {periodic!r} must name the periodic axes, each once: a string of x, y "
            "and z (e.g. 'x' or 'xyz'), True for all, False or 'none' for none"
        )
    return tuple(a in letters for a in AXES)  # type: ignore[return-value]


def periodic_text(periodic: Periodic) -> str:
    """The periodic axes' letters, x first ("" for none)."""
    return "".join(a for a in "xyz" if periodic[AXES.index(a)])


# -- which voxels a step shows -----------------------------------------------------------------
@dataclass(frozen=True)
class Mask:
    """What a step shows: `value >= threshold` (kind "threshold", data units), or the data TF's
    opacity at the value normalised over `value_range` above `threshold` (kind "opacity")."""

    kind: str
    threshold: float
    data_tf: DataTF | None = None
    value_range: tuple[float, float] | None = None

    @classmethod
    def of_threshold(cls, threshold: object) -> Mask:
        """Voxels whose value is at least `threshold` (a finite number in data units)."""
        value = _finite(threshold, "threshold", "a value in data units, e.g. threshold=0.3")
        return cls("threshold", value)

    @classmethod
    def of_tf(cls, data_tf: DataTF, value_range: tuple[float, float], opacity: object) -> Mask:
        """Voxels whose opacity under `data_tf`, values normalised over `value_range`, exceeds
        `opacity` (0 <= opacity < 1; 0: every voxel the TF does not hide)."""
        value = _finite(opacity, "opacity", "an opacity in [0, 1), e.g. opacity=0.1")
        if not 0.0 <= value < 1.0:
            raise InvalidParameterError(
                f"opacity {value:g} is outside [0, 1): a voxel is shown where the TF's "
                "opacity exceeds it; e.g. opacity=0.1"
            )
        lo, hi = (float(v) for v in value_range)
        return cls("opacity", value, data_tf, (lo, hi))

    def __call__(self, values: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """The shown voxels of `values` (Z, Y, X) as a bool array (written into `out` where
        given, a bool array of their shape), a few z rows at a time (the temporaries of a large
        step stay small)."""
        if out is None and (values.ndim != 3 or values.size <= CHUNK):
            return self._shown(values)
        shown = np.empty(values.shape, bool) if out is None else out
        if values.ndim != 3:
            shown[...] = self._shown(values)
            return shown
        rows = max(1, CHUNK // max(1, values[0].size))
        for z in range(0, values.shape[0], rows):
            shown[z : z + rows] = self._shown(values[z : z + rows])
        return shown

    def _shown(self, values: np.ndarray) -> np.ndarray:
        if self.kind == "threshold":
            return (values >= self.threshold) & np.isfinite(values)  # NaN compares False
        assert self.data_tf is not None and self.value_range is not None
        u = normalize(values, *self.value_range)
        finite = np.isfinite(values)  # +inf normalises to 1: shown nowhere either
        u[~finite] = 0.0  # lut_lerp32 indexes by u: a NaN is looked up as 0, then dropped
        alpha = lut_lerp32(self.data_tf.lut[:, 3:4], u)[..., 0]
        return (alpha > np.float32(self.threshold)) & finite

    def to_dict(self) -> dict:
        if self.kind == "threshold":
            return {"kind": "threshold", "threshold": self.threshold}
        assert self.data_tf is not None and self.value_range is not None
        return {
            "kind": "opacity",
            "opacity": self.threshold,
            "value_range": list(self.value_range),
            "data_tf": self.data_tf.to_dict(),
        }

    def describe(self) -> str:
        if self.kind == "threshold":
            return f"value >= {self.threshold:g}"
        lo, hi = self.value_range or (0.0, 1.0)
        return f"TF opacity > {self.threshold:g} (values {lo:.4g} to {hi:.4g})"


def _finite(value: object, what: str, example: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise InvalidParameterError(f"{what} {value!r} is not a number; give {example}")
    if not math.isfinite(float(value)):
        raise InvalidParameterError(f"{what} {value!r} is not finite; give {example}")
    return float(value)


# -- features ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class Feature:
    """One connected component of a step.

    `bbox_zyx` is ((z0, z1), (y0, y1), (x0, x1)), ends excluded. On an axis the feature wraps
    across (`wraps`, the axes' letters) the box runs through the periodic face, so its end may
    exceed the axis' size, and the centroid is the mean of those unwrapped indices taken back
    into [0, size); a feature that closes on itself around the axis has the box (0, size) and
    the circular mean as its centroid there.
    """

    step: int
    id: int
    size: int
    value_sum: float
    centroid_zyx: tuple[float, float, float]
    world_xyz: tuple[float, float, float]
    bbox_zyx: tuple[tuple[int, int], tuple[int, int], tuple[int, int]]
    touches_boundary: bool
    wraps: str = ""

    def to_dict(self) -> dict:
        return {
            "step": self.step,
            "id": self.id,
            "size": self.size,
            "value_sum": self.value_sum,
            "centroid_zyx": list(self.centroid_zyx),
            "world_xyz": list(self.world_xyz),
            "bbox_zyx": [list(b) for b in self.bbox_zyx],
            "touches_boundary": self.touches_boundary,
            "wraps": self.wraps,
        }


@dataclass(frozen=True)
class StepFeatures:
    """A labelled step: `labels` (Z, Y, X) uint32, 0 outside the features, k for feature k
    (features numbered 1.. in the order of their first voxel, z slowest), and the features;
    `voxels`, where known, the flat (raster order) indices of the voxels in a feature,
    ascending, so that matching need not scan the whole step again."""

    step: int
    labels: np.ndarray
    features: tuple[Feature, ...]
    voxels: np.ndarray | None = None


def label_step(
    values: np.ndarray,
    mask: Mask,
    step: int = 0,
    connectivity: int = 26,
    periodic: Periodic = NOT_PERIODIC,
    spacing_xyz: Sequence[float] = (1.0, 1.0, 1.0),
    origin_xyz: Sequence[float] = (0.0, 0.0, 0.0),
    scratch: np.ndarray | None = None,
) -> StepFeatures:
    """The features of one step's `values` (Z, Y, X) under `mask`; `scratch`, a bool array of
    their shape, holds the mask (a caller labelling step after step passes the same one)."""
    # an axis of one or two voxels has no face to wrap across (its voxels are neighbours
    # already): nothing wraps there, though its faces are no boundary either
    wrapping = tuple(p and n > 2 for p, n in zip(periodic, values.shape, strict=True))
    shown = mask(values, scratch)
    labels, wraps = label(shown, connectivity, wrapping)  # type: ignore[arg-type]
    voxels = np.flatnonzero(shown)  # every shown voxel is in a feature
    del shown
    found = measure(labels, values, step, periodic, wraps, spacing_xyz, origin_xyz, voxels)
    return StepFeatures(step, labels, found, voxels)


def label(
    shown: np.ndarray, connectivity: int = 26, periodic: Periodic = NOT_PERIODIC
) -> tuple[np.ndarray, dict[int, str]]:
    """The components of the bool array `shown` (Z, Y, X) as uint32 labels 1..n, and for each
    component that joins across a periodic face the axes it joins across."""
    if np.ndim(shown) != 3:
        raise InvalidParameterError(f"a step must be (Z, Y, X); got shape {np.shape(shown)}")
    cc3d = extra.cc3d()
    labels, n = cc3d.connected_components(
        np.ascontiguousarray(shown, dtype=bool),
        connectivity=check_connectivity(connectivity),
        return_N=True,
        out_dtype=np.uint32,
    )
    if n == 0 or not any(periodic):
        return labels, {}
    union = extra.networkx().utils.UnionFind()  # the labels facing across a face alone (all
    # of them: 45 bytes a voxel on noise, over the 13 a step's labelling is planned at)
    crossed: dict[int, set[str]] = {}
    for a, b, axes in facing_pairs(labels, connectivity, periodic):
        union.union(a, b)
        crossed.setdefault(a, set()).update(axes)
    lut = np.arange(n + 1, dtype=np.uint32)
    for group in union.to_sets():
        lut[list(group)] = min(group)  # the first voxel's label keeps the raster order
    _, renumbered = np.unique(lut, return_inverse=True)
    renumbered = renumbered.astype(np.uint32)
    wraps: dict[int, set[str]] = {}
    for old, axes in crossed.items():
        wraps.setdefault(int(renumbered[old]), set()).update(axes)
    labels = renumbered[labels]
    return labels, {k: "".join(a for a in AXES if a in v) for k, v in wraps.items()}


def offsets(connectivity: int) -> list[tuple[int, int, int]]:
    """Half of the neighbour offsets of `connectivity` (one of each pair ±d), z first."""
    most = {6: 1, 18: 2, 26: 3}[connectivity]
    return [
        d
        for d in itertools.product((-1, 0, 1), repeat=3)
        if 0 < sum(map(abs, d)) <= most and d > (0, 0, 0)  # d > 0: its first non-zero is +1
    ]


def facing_pairs(
    labels: np.ndarray, connectivity: int, periodic: Periodic
) -> Iterator[tuple[int, int, str]]:
    """Label pairs (a, b) that are neighbours across a periodic face, each with the axes the
    neighbour step crosses (a == b: a component meeting itself around the volume)."""
    shape = labels.shape
    for d in offsets(connectivity):
        # Per axis, the runs of voxels whose neighbour at +d stays inside, and the face whose
        # neighbour lies across the wrap: (source slice, neighbour slice, crosses).
        choices = []
        for n, step in zip(shape, d, strict=True):
            if step == 0:
                choices.append([(slice(None), slice(None), False)])
            elif step > 0:
                choices.append(
                    [(slice(0, n - 1), slice(1, n), False), (slice(n - 1, n), slice(0, 1), True)]
                )
            else:
                choices.append(
                    [(slice(1, n), slice(0, n - 1), False), (slice(0, 1), slice(n - 1, n), True)]
                )
        for combo in itertools.product(*choices):
            crosses = [c for _, _, c in combo]
            if not any(crosses) or any(c and not p for c, p in zip(crosses, periodic, strict=True)):
                continue  # inside (labelled already), or across a face that does not wrap
            a = labels[tuple(s for s, _, _ in combo)]
            b = labels[tuple(t for _, t, _ in combo)]
            both = (a > 0) & (b > 0)
            if not both.any():
                continue
            pairs = np.unique(np.stack([a[both], b[both]], axis=1), axis=0)
            axes = "".join(ax for ax, c in zip(AXES, crosses, strict=True) if c)
            for x, y in pairs.tolist():
                yield int(x), int(y), axes


def measure(
    labels: np.ndarray,
    values: np.ndarray,
    step: int,
    periodic: Periodic = NOT_PERIODIC,
    wraps: dict[int, str] | None = None,
    spacing_xyz: Sequence[float] = (1.0, 1.0, 1.0),
    origin_xyz: Sequence[float] = (0.0, 0.0, 0.0),
    voxels: np.ndarray | None = None,
) -> tuple[Feature, ...]:
    """The features of `labels` (1..n) with their sizes, value sums, centroids and boxes.

    Measured over the features' voxels alone (`voxels`: their flat indices, ascending; found
    here when not given), a few million at a time: the work follows the shown voxels, not the
    volume, and no float64 copy of the step is made."""
    wraps = wraps or {}
    n = int(labels.max(initial=0))
    if n == 0:
        return ()
    shape = labels.shape
    flat_labels, flat_values = labels.reshape(-1), values.reshape(-1)
    if voxels is None:
        voxels = np.flatnonzero(flat_labels)
    sizes = np.zeros(n + 1, np.int64)
    sums = np.zeros(n + 1, np.float64)
    coord_sums = np.zeros((3, n + 1), np.float64)
    lows = np.full((3, n + 1), np.iinfo(np.int64).max, np.int64)
    highs = np.full((3, n + 1), -1, np.int64)
    for start in range(0, voxels.size, CHUNK):
        where = voxels[start : start + CHUNK]
        owner = flat_labels[where]
        sizes += np.bincount(owner, minlength=n + 1)
        sums += np.bincount(owner, weights=flat_values[where], minlength=n + 1)
        for axis, index in enumerate(np.unravel_index(where, shape)):
            coord_sums[axis] += np.bincount(owner, weights=index, minlength=n + 1)
            np.minimum.at(lows[axis], owner, index)
            np.maximum.at(highs[axis], owner, index)
    centroids = np.zeros((n + 1, 3), np.float64)
    centroids[1:] = (coord_sums[:, 1:] / sizes[1:]).T
    boxes: list = [None] + [
        [(int(lows[a, k]), int(highs[a, k]) + 1) for a in range(3)] for k in range(1, n + 1)
    ]
    if wraps:
        _unwrap(labels, wraps, centroids, boxes)
    edge = [not p and size > 1 for p, size in zip(periodic, shape, strict=True)]
    spacing = np.asarray(spacing_xyz, np.float64)[::-1]
    origin = np.asarray(origin_xyz, np.float64)[::-1]
    found = []
    for k in range(1, n + 1):
        box = boxes[k]
        touches = any(
            e and (lo == 0 or hi == size)
            for e, (lo, hi), size in zip(edge, box, shape, strict=True)
        )
        centroid = centroids[k]
        world = origin + centroid * spacing
        found.append(
            Feature(
                step=step,
                id=k,
                size=int(sizes[k]),
                value_sum=float(sums[k]),
                centroid_zyx=tuple(float(c) for c in centroid),  # type: ignore[arg-type]
                world_xyz=tuple(float(w) for w in world[::-1]),  # type: ignore[arg-type]
                bbox_zyx=tuple((int(lo), int(hi)) for lo, hi in box),  # type: ignore[arg-type]
                touches_boundary=bool(touches),
                wraps=wraps.get(k, ""),
            )
        )
    return tuple(found)


def _unwrap(
    labels: np.ndarray, wraps: dict[int, str], centroids: np.ndarray, boxes: list[list]
) -> None:
    """Centroid and box, on each axis a component wraps across, from its unwrapped indices."""
    ids = np.array(sorted(wraps), dtype=labels.dtype)
    where = np.nonzero(np.isin(labels, ids))
    owner = labels[where]
    for k in ids.tolist():
        mine = owner == k
        for axis, letter in enumerate(AXES):
            if letter not in wraps[k]:
                continue
            size = labels.shape[axis]
            coords = where[axis][mine].astype(np.float64)
            occupied = np.unique(coords)
            if len(occupied) == size:  # around the whole axis: no gap to cut it at
                angle = coords * (2 * np.pi / size)
                mean = np.arctan2(np.sin(angle).mean(), np.cos(angle).mean())
                centroids[k, axis] = (mean * size / (2 * np.pi)) % size
                boxes[k][axis] = (0, size)
                continue
            # Cut the axis at its widest empty run: the component lies in one piece after it.
            gaps = np.diff(np.append(occupied, occupied[0] + size))
            start = occupied[(int(np.argmax(gaps)) + 1) % len(occupied)]
            unwrapped = np.where(coords < start, coords + size, coords)
            centroids[k, axis] = unwrapped.mean() % size
            boxes[k][axis] = (int(start), int(unwrapped.max()) + 1)
