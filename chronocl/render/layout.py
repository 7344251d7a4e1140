"""The sizes of the annotations drawn on pictures, in one place (issue 47): the axis triad
(`chronocl.render.triad`), event markers (`chronocl.render.markers`), the legends and captions
around a panel (`chronocl.render.legends`, `chronocl.render.panels`) and the box's axes with
their ticks (`chronocl.viewer.box_axes`).

These are layout, not tuning: chosen by eye on rendered pictures and the viewer's panels, never
timed. Code reads them as `LAYOUT.field`. The page draws the box's ticks with the same numbers
(chronocl/viewer/static/box_axes.js): change both.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Layout:
    """Annotation sizes (one instance: `LAYOUT`); pixels are the picture's."""

    # The axis triad: its square's side as a fraction of the panel's shorter side, the side
    # below which its letters cannot be read (a panel too small for it gets none), the letters'
    # font size at least, and how much larger its arrows are drawn before being scaled down
    # (smooth lines).
    triad_fraction: float = 0.12
    triad_min_px: int = 32
    triad_letter_min_px: int = 10
    triad_supersample: int = 4

    # An event marker's ring: its radius as a fraction of the panel's shorter side, and at least.
    ring_fraction: float = 0.018
    ring_min_px: int = 4

    # A legend band as wide as this many digits holds a time legend and a colour bar side by
    # side, the time legend taking time_share of its width; a caption wraps onto at most
    # caption_lines lines, then ends in '…'.
    beside_min_digits: int = 64
    time_share: float = 0.55
    caption_lines: int = 3

    # The box's axes: an edge shorter than edge_min_px on the panel is seen end-on (no ticks),
    # ticks along an edge lie about tick_gap_px apart at least. As box_axes.js draws them: a
    # tick mark's length outwards from its edge, a tick label's gap from the edge, and an axis
    # name's gap beyond its tick labels.
    edge_min_px: int = 40
    tick_gap_px: int = 50
    tick_px: int = 5
    tick_label_gap_px: int = 8
    axis_name_gap_px: int = 8
    # About how far a tick label reaches beyond its gap (the page's 11 px font, a few digits):
    # across one set off sideways, down one set off downwards. Only to judge whether an edge's
    # labels have room on the panel; the page and `draw_axes` measure the labels they draw.
    tick_label_w_px: int = 30
    tick_label_h_px: int = 14


LAYOUT = Layout()
