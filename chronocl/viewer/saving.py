"""Save actions: the shown views as one annotated PNG (as `chronocl render` draws them: each
panel captioned with its mode and window over its time legend or count bar and data colour bar,
and a title naming the data set and the window, also kept in the PNG's text), or one view's
chronovolume as a zipped zarr store, each kept in `Downloads` under a random key for the page
to fetch."""

from __future__ import annotations

import secrets
import shutil
import tempfile
import threading
import zipfile
from pathlib import Path

import numpy as np

from chronocl.core.selection import Selection
from chronocl.data.bricks import SeriesBricks
from chronocl.data.chronovolume import Chronovolume
from chronocl.data.series import TimeSeries
from chronocl.engine.base import Engine
from chronocl.integration.inmemory import Job, integrate_bricks
from chronocl.render.image import Image
from chronocl.render.panels import Layout, compose
from chronocl.render.views import describe, title_text


class Downloads:
    """Files prepared for download (a saved image or chronovolume), by random key."""

    MAX = 16

    def __init__(self) -> None:
        self.dir = Path(tempfile.mkdtemp(prefix="chronocl-viewer-"))
        self._items: dict[str, tuple[Path, str, str]] = {}
        self._lock = threading.Lock()

    def add(self, data: bytes | Path, filename: str, media_type: str) -> str:
        key = secrets.token_urlsafe(16)
        path = self.dir / key
        if isinstance(data, Path):
            data.replace(path)
        else:
            path.write_bytes(data)
        with self._lock:
            self._items[key] = (path, filename, media_type)
            while len(self._items) > self.MAX:
                old = next(iter(self._items))
                self._items.pop(old)[0].unlink(missing_ok=True)
        return key

    def get(self, key: str) -> tuple[Path, str, str] | None:
        with self._lock:
            return self._items.get(key)

    def close(self) -> None:
        shutil.rmtree(self.dir, ignore_errors=True)


def zip_store(store: Path, archive: Path) -> None:
    """A zarr directory store as a zip whose root is the store's root (zarr's ZipStore reads it)."""
    with zipfile.ZipFile(archive, "w", zipfile.ZIP_STORED) as zf:
        for path in sorted(store.rglob("*")):
            if path.is_file():
                zf.write(path, path.relative_to(store).as_posix())


def picture(
    panels: list[np.ndarray],
    cvs: list[Chronovolume],
    background: tuple,
    columns: int | None = None,
    name: str | None = None,
    time_labels: str = "labels",
) -> tuple[Image, Layout]:
    """The panels in a grid of `columns` per row (as the page lays them out), each captioned
    with its chronovolume and over its own legend, under a title naming the data set `name`
    and the windows shown (none without a name): an `Image` whose PNG also holds the title and
    captions as Title and Description text (the viewer's Save PNG and movie frames, `chronocl
    render --state`), and where its parts lie."""
    captions = [describe(cv) for cv in cvs]
    title = None if name is None else title_text(name, cvs, time_labels)
    array, layout = compose(panels, captions, cvs, columns, background, time_labels, title=title)
    text = {"Description": "\n".join(captions), "Software": "chronocl"}
    if title is not None:
        text["Title"] = title
    return Image(array, text), layout


def save_image(
    downloads: Downloads,
    panels: list[np.ndarray],
    cvs: list[Chronovolume],
    background: tuple,
    filename: str,
    columns: int | None = None,
    name: str | None = None,
) -> tuple[str, Layout]:
    """`picture` as a PNG download; the download's key and the layout."""
    image, layout = picture(panels, cvs, background, columns, name)
    return downloads.add(image.png_bytes(), filename, "image/png"), layout


def full_precision(
    cv: Chronovolume, series: TimeSeries, engine: Engine, budget: int
) -> Chronovolume:
    """`cv` as `chronocl integrate` writes it: a display chronovolume (RGBA8, the viewer's
    full-resolution frame) integrated again in float32 from `series`, in z-slabs whose bricks
    take a quarter of `budget` bytes at most; others as they are."""
    if cv.rgba_dtype != np.uint8:  # (a GPU recolour's RGBA8 is not read back for it)
        return cv
    meta, spec = cv.metadata, cv.spec
    level = int(meta.get("level") or 0)
    src = series.level(level, spec.integration.pool) if level else series
    job = Job.of(src, Selection(cv.steps, src.n_steps), spec, tuple(meta["value_range"]))
    rows = max(1, budget // (4 * max(1, job.row_bytes)))  # slabs of the budget, as streamed
    return integrate_bricks(job, engine, SeriesBricks(src), slab=rows)


def save_chronovolume(downloads: Downloads, cv: Chronovolume, name: str) -> str:
    """The chronovolume as a zipped zarr store download."""
    with tempfile.TemporaryDirectory(dir=downloads.dir) as tmp:
        store = cv.save(Path(tmp) / "chronovolume.zarr")
        archive = Path(tmp) / "chronovolume.zip"
        zip_store(store, archive)
        return downloads.add(archive, name, "application/zip")
