"""What a frame is made of besides the draws: the size the panels are drawn at (the page's
panel size in device pixels, within a pixel budget), JPEG encoding of the panels, the preview
scale and qualities, the legend of the window's time colours that the page's timeline shows,
and the note a panel gets when almost nothing in it is visible."""

from __future__ import annotations

import io

import numpy as np

from chronocl.data.chronovolume import Chronovolume

PREVIEW_SCALE = 0.5
JPEG_QUALITY = {"preview": 70, "full": 88}
# Drawing time grows with the pixels drawn (llvmpipe: ~140 ms for a 128^3 volume at 512^2,
# docs/display.md), so a frame draws at most as many pixels, over all its views, as the
# largest single panel the page asked for before its panels filled the view area (768^2).
# Larger panels show the frame scaled up; saved PNGs are drawn at the panel's full size.
PIXEL_BUDGET = 768 * 768
EMPTY_BELOW = 0.01  # a panel with less than this fraction of visible pixels gets a note


def render_size(size: tuple[int, int], n_views: int, scale: float = 1.0) -> tuple[int, int]:
    """The size each of `n_views` panels of `size` (w, h) is drawn at: `scale` of it, shrunk
    (same aspect) so that all views together stay within `PIXEL_BUDGET`, at least 32 px."""
    w, h = size[0] * scale, size[1] * scale
    fit = min(1.0, (PIXEL_BUDGET / max(1.0, w * h * n_views)) ** 0.5)
    return max(32, int(w * fit)), max(32, int(h * fit))


def visible_fraction(pixels: np.ndarray, background: tuple[float, float, float]) -> float:
    """The fraction of a drawn panel's pixels that differ visibly from the background
    (every 4th pixel each way: a cheap estimate)."""
    sample = pixels[::4, ::4, :3].astype(np.int16)
    bg = np.array([round(255 * c) for c in background[:3]], dtype=np.int16)
    return float((np.abs(sample - bg).max(axis=-1) > 24).mean())


def empty_note(mode: str, summary: str, visible: float) -> str | None:
    """Why a panel shows (almost) nothing, when less than `EMPTY_BELOW` of it is visible."""
    if visible >= EMPTY_BELOW:
        return None
    return (
        f"{mode}: almost nothing is visible ({100 * visible:.1f} % of the view). "
        f"This mode shows the {summary}; the values it keeps fall mostly where the data "
        "transfer function is transparent. Raise the opacity of lower values in the data "
        "transfer function, or choose another mode."
    )


def encode(pixels: np.ndarray, quality: int) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(pixels).save(buf, format="JPEG", quality=quality)
    return buf.getvalue()


def legend(cv: Chronovolume) -> list[dict]:
    """Each selected step's time colour and opacity (the timeline colours its ticks by them)."""
    spec = cv.spec
    steps = cv.steps
    n = cv.metadata["selection"]["n_steps"]
    rgb, alpha = spec.time_tf.evaluate(spec.time_tf.positions_of(steps, n))
    return [
        {
            "step": int(s),
            "rgb": [round(float(c), 3) for c in rgb[k]],
            "a": round(float(alpha[k]), 3),
        }
        for k, s in enumerate(steps)
    ]
