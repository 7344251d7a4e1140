"""What a frame is made of besides the draws: the size the panels are drawn at (the page's
panel size in device pixels, within a pixel budget that follows the latency target), JPEG
encoding of the panels, the preview scale and qualities, the legend of the window's time
colours that the page's timeline shows, the data colour bar of a coloured data TF, the count
bar that stands for the time legend in a mode whose colour tells the fraction of steps (count),
the note a panel gets when almost nothing in it is visible, and the times its work took beside
integrating (`FrameTimes`)."""

from __future__ import annotations

import io
from dataclasses import dataclass, fields

import numpy as np

from chronocl.core.tuning import TUNING, running
from chronocl.data.chronovolume import Chronovolume
from chronocl.render.colorbar import data_bar
from chronocl.render.legends import FRACTION_ENDS, fraction_ramp

COLOUR_BAR_SAMPLES = 64  # colours a colour bar sends (the page draws a gradient through them)
JPEG_QUALITY = {"preview": 70, "full": 88}
# Drawing time grows with the pixels drawn (llvmpipe: ~80-140 ms for a 128^3 volume at 512^2,
# docs/display.md). A frame answering input draws as many pixels, over all its views, as
# `DrawBudget` predicts to take `TUNING.draw_target_ms`; once input stops the frame is redrawn
# with up to `TUNING.pixel_budget` pixels (beyond that the browser scales a frame up to its
# panels), never fewer than `TUNING.min_pixels`. Saved PNGs are drawn at the panels' full size.
# A full-resolution frame whose full-size draw fits the frame's latency target
# (`TUNING.target_ms`) is drawn at full size at once, not reduced and redrawn, and so is one
# predicted within `TUNING.sharp_overrun` times that.


@dataclass
class FrameTimes:
    """What a frame's work took beside integrating and drawing, in ms, for its header's
    `timings`: summed by whatever does the work (`Recolouring`, `InTexture`, `Views`) and
    zeroed once, as the worker starts a frame or a refine (`start`)."""

    recolour_ms: float = 0.0  # a TF edit's recolouring, less the texture writes and reads
    recolour_upload_ms: float = 0.0  # a recolour's texture writes (llvmpipe's brick-wise path)
    readback_ms: float = 0.0  # recoloured RGBA read back from textures (a probe's came before)
    slab_upload_ms: float = 0.0  # a refine's texture writes, overlapped with its integration
    read_ms: float = 0.0  # of integrating, waiting for the windows' steps to be read

    def start(self) -> None:
        for f in fields(self):
            setattr(self, f.name, 0.0)


class DrawBudget:
    """How many pixels a frame may draw to meet `target_ms`, learnt from the frames drawn
    (milliseconds per pixel, a running estimate). Before the first draw: `cap`."""

    def __init__(
        self,
        target_ms: float | None = None,  # None: TUNING.draw_target_ms
        floor: int | None = None,  # None: TUNING.min_pixels
        cap: int | None = None,  # None: TUNING.pixel_budget
        sharp_ms: float | None = None,  # None: TUNING.target_ms
    ) -> None:
        self.target_ms = TUNING.draw_target_ms if target_ms is None else target_ms
        self.floor = TUNING.min_pixels if floor is None else floor
        self.cap = TUNING.pixel_budget if cap is None else cap
        self.sharp_ms = TUNING.target_ms if sharp_ms is None else sharp_ms
        self.ms_per_pixel: float | None = None

    def record(self, ms: float, pixels: int) -> None:
        if pixels < 16 * 16 or not ms > 0:
            return
        self.ms_per_pixel = running(self.ms_per_pixel, ms / pixels)

    def pixels(self, sharp: bool = False, full: int | None = None) -> int:
        """Pixels drawn in the target (`sharp`: a full-resolution frame's, `sharp_ms`; one
        whose `full` pixels are predicted within `TUNING.sharp_overrun` times that: `cap`)."""
        if self.ms_per_pixel is None:
            return self.cap
        if (
            sharp
            and full is not None
            and full * self.ms_per_pixel <= TUNING.sharp_overrun * self.sharp_ms
        ):
            return self.cap
        target = self.sharp_ms if sharp else self.target_ms
        return int(min(self.cap, max(self.floor, target / self.ms_per_pixel)))


def render_size(
    size: tuple[int, int], n_views: int, scale: float = 1.0, budget: int | None = None
) -> tuple[int, int]:
    """The size each of `n_views` panels of `size` (w, h) is drawn at: `scale` of it, shrunk
    (same aspect) so that all views together stay within `budget` pixels (None:
    `TUNING.pixel_budget`), at least 32 px."""
    budget = TUNING.pixel_budget if budget is None else budget
    w, h = size[0] * scale, size[1] * scale
    fit = min(1.0, (budget / max(1.0, w * h * n_views)) ** 0.5)
    return max(32, int(w * fit)), max(32, int(h * fit))


def visible_fraction(pixels: np.ndarray, background: tuple[float, float, float]) -> float:
    """The fraction of a drawn panel's pixels that differ visibly from the background
    (every 4th pixel each way: a cheap estimate)."""
    sample = pixels[::4, ::4, :3].astype(np.int16)
    bg = np.array([round(255 * c) for c in background[:3]], dtype=np.int16)
    return float((np.abs(sample - bg).max(axis=-1) > 24).mean())


def empty_note(mode: str, summary: str, visible: float) -> str | None:
    """Why a panel shows (almost) nothing, when less than `TUNING.empty_panel_fraction` of it is
    visible."""
    if visible >= TUNING.empty_panel_fraction:
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


def colour_bar(cv: Chronovolume) -> dict | None:
    """A view's data colour bar (`chronocl.render.colorbar`) for the page's legend: its title,
    the value range the chronovolume used (data units) and the data TF's colours over it as
    #rrggbb; None where the data TF is plain white (colour tells time alone)."""
    bar = data_bar(cv)
    if bar is None:
        return None
    rgb = np.clip(np.round(bar.rgb(COLOUR_BAR_SAMPLES) * 255), 0, 255).astype(int)
    return {
        "title": bar.title,
        "range": [bar.lo, bar.hi],
        "colors": ["#{:02x}{:02x}{:02x}".format(*c) for c in rgb.tolist()],
    }


def count_bar(cv: Chronovolume) -> dict | None:
    """The legend of a view whose mode colours by the fraction of steps (`Mode.legend` is
    "fraction": count), for the page to draw instead of the time legend, as the saved PNG
    does (`chronocl.render.legends`): the data TF's colours as the bar shows them and its
    opacity at COLOUR_BAR_SAMPLES fractions from 0 to 1, what the ends mean and the window's
    number of steps; None where colour tells time."""
    spec = cv.spec
    if spec.integration.legend != "fraction":
        return None
    shown, alpha = fraction_ramp(spec.data_tf, COLOUR_BAR_SAMPLES)
    rgb = np.clip(np.round(shown * 255), 0, 255).astype(int)
    return {
        "kind": "fraction",
        "steps": len(cv.steps),
        "ends": list(FRACTION_ENDS),
        "colors": ["#{:02x}{:02x}{:02x}".format(*c) for c in rgb.tolist()],
        "alpha": [round(float(a), 3) for a in alpha],
    }
