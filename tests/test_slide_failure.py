"""A slide that fails half way (the device or the host out of memory while the sliding state
is updated): the session must not show the old window's chronovolume for the new window, nor
slide on from the half-updated state; the next request integrates the window anew."""

from __future__ import annotations

import numpy as np
import pytest

import chronocl
from chronocl.core.errors import SupersededError
from chronocl.core.interrupt import interruptible
from chronocl.core.tf import TimeTF
from chronocl.engine.opencl import OpenCLEngine
from chronocl.integration.interactive.session import Session

from .test_opencl import assert_same

pytestmark = pytest.mark.filterwarnings("ignore::chronocl.core.errors.ChronoclWarning")


class FailingOnce:
    """Raises MemoryError (what pyopencl and numpy raise out of memory) at the `at`-th call."""

    def __init__(self, fn, at: int) -> None:
        self.fn, self.at, self.calls = fn, at, 0

    def __call__(self, *args, **kwargs):
        self.calls += 1
        if self.calls == self.at:
            raise MemoryError("out of device memory")
        return self.fn(*args, **kwargs)


def _reference(session: Session, series):
    return chronocl.integrate(series, session.window(), spec=session.spec, engine="numpy")


@pytest.mark.parametrize("host_ptr", [True, False])
@pytest.mark.parametrize(("mode", "hook"), [("alpha", "combine"), ("mean", "fixed_add")])
def test_a_slide_that_fails_half_way_is_not_shown_nor_slid_on(host_ptr, mode, hook):
    rng = np.random.default_rng(7)
    series = chronocl.TimeSeries.from_array(rng.random((12, 4, 5, 19), dtype=np.float32))
    engine = OpenCLEngine(host_ptr=host_ptr)
    rgb = TimeTF.preset("rgb", positions="absolute")
    with Session(series, mode=mode, time_tf=rgb, engine=engine, memory="64MB") as session:
        session.set_window(2, 8)
        session.slide(1)  # the sliding state is built
        assert session.stats["path"] == "incremental"
        failing = FailingOnce(getattr(engine, hook), 2)  # half way through the next slide
        setattr(engine, hook, failing)
        try:
            with pytest.raises(MemoryError):
                session.slide(1)
        finally:
            setattr(engine, hook, failing.fn)
        assert failing.calls >= 2
        assert_same(session.current(), _reference(session, series))
        for k in (1, -2):
            assert_same(session.slide(k), _reference(session, series))


@pytest.mark.parametrize(
    ("mode", "pieces"), [("alpha", 0), ("alpha", 5), ("additive", 2), ("max", 7), ("change", 1)]
)
def test_a_slide_given_up_for_newer_input_is_not_shown_nor_slid_on(mode, pieces):
    """A refine's slide (inside `interruptible`) is given up between its leaves and combines
    once newer input comes: the first slide after an edit fills the whole state (seconds at
    users' sizes, where a key pressed meanwhile waited for all of it). Its progress is told
    as "sliding" parts; the next request integrates the window anew and slides on from there."""
    rng = np.random.default_rng(5)
    series = chronocl.TimeSeries.from_array(rng.random((16, 3, 6, 21), dtype=np.float32))
    rgb = TimeTF.preset("rgb", positions="absolute")
    with Session(series, mode=mode, time_tf=rgb, memory="64MB") as session:
        session.set_window(2, 12)
        told: list[tuple] = []

        def newer_input() -> bool:  # once `pieces` of the slide are done (reads not counted:
            # a wait for the entering step checks in as often as it polls)
            return sum(stage == "sliding" for stage, _, _ in told) >= pieces

        with (
            pytest.raises(SupersededError),
            interruptible(newer_input, lambda *p: told.append(p)),
        ):
            session.slide(1)  # the first: fills the sliding state, leaf by leaf
        sliding = [p for p in told if p[0] == "sliding"]
        assert sliding == [("sliding", i, 20) for i in range(pieces)]
        assert_same(session.current(), _reference(session, series))
        # Given up before the state was touched (no piece: while the entering step was read),
        # the window slides on from it; given up half way, it is integrated anew.
        assert session.stats["path"] == ("incremental" if pieces == 0 else "reintegrate")
        for k in (1, 1, -3):
            assert_same(session.slide(k), _reference(session, series))
            assert session.stats["path"] == "incremental"
