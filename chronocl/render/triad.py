"""The axis triad: the data's x, y and z axes as small red, green and blue arrows with their
letters, drawn in a corner of a rendered panel from the camera's rotation, so a picture says
which way its data lie.

The triad's square is `LAYOUT.triad_fraction` of the panel's shorter side, at its bottom-right
corner (where the viewer draws its own, chronocl/viewer/static/orientation.js, in the same
colours); at zoom 1 the framed volume's bounding sphere leaves that corner empty. Panels too
small for a legible triad (`LAYOUT.triad_min_px` pixels would cover more than a quarter of their
shorter side) get none. Arrows and letters have a dark rim, so they read on black and on white
backgrounds; an axis pointing away from the viewer is drawn fainter, the nearest last.
"""

from __future__ import annotations

import numpy as np

from chronocl.render.camera import Camera
from chronocl.render.layout import LAYOUT

AXIS_COLOURS = ((255, 90, 90), (90, 214, 90), (90, 155, 255))  # x, y, z, as the viewer's
RIM = (0, 0, 0)


def triad_size(width: int, height: int) -> int:
    """The side of the triad's square on a panel of width x height; 0 when it gets none."""
    short = min(width, height)
    side = max(round(LAYOUT.triad_fraction * short), LAYOUT.triad_min_px)
    return side if side <= short / 4 else 0


def draw_triad(panel: np.ndarray, camera: Camera) -> np.ndarray:
    """`panel` (H, W, 3 uint8, top-down) with the axis triad of `camera`'s view in its
    bottom-right corner; the panel itself when it is too small for one."""
    from PIL import Image as PILImage
    from PIL import ImageDraw

    h, w, _ = panel.shape
    side = triad_size(w, h)
    if not side:
        return panel
    supersample = LAYOUT.triad_supersample
    big = side * supersample
    arrows = PILImage.new("RGBA", (big, big), (0, 0, 0, 0))  # drawn large, then scaled down
    letters = PILImage.new("RGBA", (side, side), (0, 0, 0, 0))  # hinted at their own size
    draw, write = ImageDraw.Draw(arrows), ImageDraw.Draw(letters)
    font = _font(max(LAYOUT.triad_letter_min_px, round(side * 0.24)))
    reach = 0.25  # arrow length, of the square's side; the letters sit beyond it
    head = 0.12  # arrowhead length
    width = max(2, round(big * 0.05))
    right, up, towards = camera.screen_axes()
    # Farthest axis first, so the nearer ones are drawn over it.
    for axis in sorted(range(3), key=lambda a: towards[a]):
        d = np.array([right[axis], -up[axis]])  # screen y grows downwards
        alpha = 170 if towards[axis] < -0.2 else 255  # pointing away from the viewer: fainter
        colour = (*AXIS_COLOURS[axis], alpha)
        dark = (*RIM, 190)  # the rim stays: a faint arm still reads on white
        centre, tip = np.array([big / 2] * 2), big / 2 + d * reach * big
        headed = float(np.hypot(*d)) * reach > 1.5 * head  # long enough to show a head
        shaft = big / 2 + d * (reach - head / 2) * big if headed else tip
        draw.line([tuple(centre), tuple(tip)], fill=dark, width=width + 2 * supersample)
        draw.line([tuple(centre), tuple(shaft)], fill=colour, width=width)
        if headed:
            unit = d / np.hypot(*d)
            across = np.array([-unit[1], unit[0]]) * head * 0.6 * big
            back = tip - unit * head * big
            corners = [tuple(tip), tuple(back + across), tuple(back - across)]
            draw.polygon(corners, fill=colour, outline=dark, width=supersample // 2)
        # The letter beyond the tip (at the centre when the axis points at the viewer).
        at = np.clip(side / 2 + d * (reach + 0.17) * side, side * 0.1, side * 0.9)
        write.text(
            tuple(at),
            "xyz"[axis],
            fill=colour,
            font=font,
            anchor="mm",
            stroke_width=1,
            stroke_fill=dark,
        )
    margin = max(2, side // 16)
    where = (w - side - margin, h - side - margin)
    out = PILImage.fromarray(panel).convert("RGBA")
    out.alpha_composite(arrows.resize((side, side), PILImage.Resampling.LANCZOS), where)
    out.alpha_composite(letters, where)
    return np.asarray(out.convert("RGB"))


def _font(size: int):
    from PIL import ImageFont

    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # Pillow without FreeType sizes
        return ImageFont.load_default()
