"""Time selections: windows with stride, explicit lists, orders, and their errors."""

from __future__ import annotations

import numpy as np
import pytest

from chronocl.core.errors import InvalidSelectionError, UnknownNameError
from chronocl.core.selection import Selection, parse_selection
from chronocl.modes.spec import IntegrationSpec, resolve_order


@pytest.mark.parametrize(
    ("text", "steps"),
    [
        ("0:10:3", (0, 3, 6, 9)),
        ("2:5", (2, 3, 4)),
        (":3", (0, 1, 2)),
        ("7:", (7, 8, 9)),
        ("1,4,8", (1, 4, 8)),
        ("5", (5,)),
    ],
)
def test_parse_strings(text, steps):
    sel = parse_selection(text, 10)
    assert sel.steps == steps
    assert parse_selection(sel.describe(), 10) == sel


def test_other_forms():
    assert parse_selection(slice(1, 7, 2), 10).steps == (1, 3, 5)
    assert parse_selection(range(1, 7, 2), 10).steps == (1, 3, 5)
    assert parse_selection([0, 9], 10).steps == (0, 9)
    assert parse_selection((0, 4, 9, 2)[:1], 10).steps == (0,)  # a 1-tuple is one step
    assert parse_selection(None, 4).steps == (0, 1, 2, 3)


@pytest.mark.parametrize("window", [(0, 10), (0, 10, 2), (np.int64(2), 5)])
def test_a_bare_tuple_of_two_or_three_is_refused_naming_both_readings(window):
    """A Python user reads (0, 10) as a range, a list as steps 0 and 10: neither is guessed."""
    numbers = [int(v) for v in window]
    with pytest.raises(InvalidSelectionError) as info:
        parse_selection(window, 12)
    message = str(info.value)
    assert "\n" not in message and "ambiguous" in message
    assert f"'{':'.join(map(str, numbers))}'" in message  # the range
    assert f"range({', '.join(map(str, numbers))})" in message
    assert str(numbers) in message  # the steps alone


def test_the_api_refuses_a_bare_pair_before_any_work():
    import chronocl

    data = np.random.default_rng(0).random((12, 2, 2, 2)).astype(np.float32)
    series = chronocl.TimeSeries.from_array(data)
    with pytest.raises(InvalidSelectionError, match=r"write '0:10' or range\(0, 10\)"):
        chronocl.integrate(series, (0, 10), engine="numpy")
    assert chronocl.integrate(series, range(0, 10), engine="numpy").steps == tuple(range(10))
    assert chronocl.integrate(series, [0, 10], engine="numpy").steps == (0, 10)


@pytest.mark.parametrize(
    ("window", "needle"),
    [
        ("0:11", "outside the series"),
        ("-1:3", "outside"),
        ("5:5", "is empty: it ends where it starts; the end is exclusive, so write 5:6"),
        ("7:2", "is reversed: write 2:7"),
        ("0:-1", "outside the series"),
        ("20:20", "outside the series"),
        ("2.0:4.5", "looks like times, but windows count steps (0 to 10)"),
        ("0:5:0", "stride must be at least 1"),
        ("3,3", "strictly increasing"),
        ("4,2", "strictly increasing"),
        ("12", "outside [0, 10)"),
        ("a:b", "cannot read"),
        ("1:2:3:4", "cannot read"),
        ([], "empty"),
    ],
)
def test_bad_windows(window, needle):
    with pytest.raises(InvalidSelectionError) as info:
        parse_selection(window, 10)
    assert needle in str(info.value)
    assert isinstance(info.value, ValueError)


def test_a_window_of_times_names_its_steps():
    """A window written in the series' time labels is refused, naming the steps they are."""
    times = [0.25 * i for i in range(10)]
    with pytest.raises(InvalidSelectionError) as info:
        parse_selection("0.5:1.25", 10, times)
    assert "the times in [0.5, 1.25) are steps 2 to 4 (0.5 to 1): write --window 2:5" in str(
        info.value
    )
    with pytest.raises(InvalidSelectionError, match="no step's time lies in"):
        parse_selection("3:4.5", 10, times)
    # labels out of order (or not finite) name no steps: they would not be the times asked
    for labels in ([3, 2, 1, 0, 5, 2.2, 6, 7, 8, 9], [*times[:9], float("nan")]):
        with pytest.raises(InvalidSelectionError, match="chronocl info STORE"):
            parse_selection("2.0:4.5", 10, labels)


def test_orders():
    sel = Selection((2, 5, 9), 10)
    np.testing.assert_array_equal(resolve_order("forward", sel), [0, 1, 2])
    np.testing.assert_array_equal(resolve_order("backward", sel), [2, 1, 0])
    np.testing.assert_array_equal(resolve_order((9, 2, 5), sel), [2, 0, 1])
    with pytest.raises(InvalidSelectionError, match="permutation"):
        resolve_order((9, 2), sel)
    with pytest.raises(UnknownNameError, match="sideways"):
        IntegrationSpec(order="sideways")
    with pytest.raises(UnknownNameError, match="unknown mode 'sum'"):
        IntegrationSpec(mode="sum")
