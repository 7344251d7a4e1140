"""What a frame is made of besides the draws: JPEG encoding of the panels, the preview scale
and qualities, and the legend of the window's time colours that the page's timeline shows."""

from __future__ import annotations

import io

import numpy as np

from chronocl.data.chronovolume import Chronovolume

PREVIEW_SCALE = 0.5
JPEG_QUALITY = {"preview": 70, "full": 88}


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
