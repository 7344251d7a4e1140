"""The tracks' colours: one qualitative palette, shared by the event graph's picture
(`chronocl.events.plot`) and track-coloured renders (`chronocl.events.colour`), so a track has
the same colour in both. Track k has colour k mod 20, whatever the window or the mode."""

from __future__ import annotations

# tab10's ten hues, then tab20's ten lighter ones (the events picture's palette), as RGB bytes
TRACK_PALETTE: tuple[tuple[int, int, int], ...] = (
    (31, 119, 180),
    (255, 127, 14),
    (44, 160, 44),
    (214, 39, 40),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
    (127, 127, 127),
    (188, 189, 34),
    (23, 190, 207),
    (174, 199, 232),
    (255, 187, 120),
    (152, 223, 138),
    (255, 152, 150),
    (197, 176, 213),
    (196, 156, 148),
    (247, 182, 210),
    (199, 199, 199),
    (219, 219, 141),
    (158, 218, 229),
)


def track_rgb(track: int) -> tuple[float, float, float]:
    """Track `track`'s colour by id, in [0, 1]."""
    r, g, b = TRACK_PALETTE[track % len(TRACK_PALETTE)]
    return r / 255, g / 255, b / 255
