"""The mode contract is checked where a mode class is defined: a class whose flags promise a
capability (`Combines`, `FinishesSums`, `ComparesValues`) without its hooks, or set a flag out
of its choices, is refused by its `class` statement (at import), with one line naming the class,
the flag and the missing hook; every registered mode has the hooks its flags promise."""

from __future__ import annotations

import importlib.util
import sys

import numpy as np
import pytest

from chronocl import modes
from chronocl.core.errors import ChronoclError, ModeDefinitionError
from chronocl.data.pyramid import POOLS
from chronocl.modes.base import (
    CAPABILITIES,
    CHOICES,
    Combines,
    ComparesValues,
    FinishesSums,
    Mode,
    Partial,
)


def _one_line(exc: pytest.ExceptionInfo) -> str:
    text = str(exc.value)
    assert "\n" not in text and isinstance(exc.value, ChronoclError | TypeError)
    return text


@pytest.mark.parametrize("name", modes.names())
def test_every_registered_mode_has_the_hooks_its_flags_promise(name):
    mode = modes.get(name)
    kind = type(mode)
    assert isinstance(mode, Combines) == kind.combines()
    assert isinstance(mode, FinishesSums) == (kind.slides == "invert")
    assert isinstance(mode, ComparesValues) == kind.compares_values
    for protocol, _, promised in CAPABILITIES:
        assert not promised(kind) or isinstance(mode, protocol), (name, protocol.__name__)


def test_the_pool_choices_are_the_pyramids_pools():
    """Modes sit below data, so the contract lists the pools itself; they must agree."""
    assert CHOICES["pool"] == POOLS


def test_a_complete_mode_defined_outside_the_registry_is_accepted_and_not_registered():
    before = modes.names()

    class Brightest(Mode):
        name = "brightest"
        summary = "a test mode"
        kernel = "extreme"
        kernel_function = "integrate_extreme"
        compares_values = True

        def accumulate(self, u, steps, order, step_rgba, spec):
            return Partial(np.zeros((*u.shape[1:], 4)), None)

        def combine(self, front, back, spec):
            return front

        def combine_kernel(self, spec):
            return "extreme", "combine_extreme", {}

        def leaf_value(self, values):
            return values.raw[-1]

        def leaf_value_kernel(self, value_range):
            return "leaf_raw", []

    assert isinstance(Brightest(), Combines) and isinstance(Brightest(), ComparesValues)
    assert modes.names() == before


def test_an_aggregating_mode_without_its_combine_kernel_fails_at_its_class_statement():
    with pytest.raises(ModeDefinitionError) as exc:

        class NoCombineKernel(Mode):
            name = "broken"
            summary = "no combine kernel"
            kernel = "alpha"
            kernel_function = "integrate_alpha"

            def accumulate(self, u, steps, order, step_rgba, spec):
                raise AssertionError("never called: the class is refused first")

            def combine(self, front, back, spec):
                return front

    text = _one_line(exc)
    assert "NoCombineKernel" in text and 'slides = "aggregate"' in text
    assert "(Combines) but does not define combine_kernel" in text


def test_an_inverting_mode_names_every_finish_hook_it_lacks():
    with pytest.raises(ModeDefinitionError, match=r"does not define finish_sums and finish_kernel"):

        class NoFinish(Mode):
            name = "broken"
            summary = "no finish"
            kernel = "count"
            kernel_function = "integrate_count"
            slides = "invert"
            state_bytes = 0
            sum_channels = 1

            def accumulate(self, u, steps, order, step_rgba, spec):
                raise AssertionError


def test_an_inverting_mode_that_aggregates_a_partial_needs_combine_too():
    """additive's shape: colour sums inverted, the opacity aggregated (state_bytes > 0)."""
    with pytest.raises(ModeDefinitionError) as exc:

        class HalfAdditive(Mode):
            name = "broken"
            summary = "sums without the aggregated opacity's combine"
            kernel = "additive"
            kernel_function = "integrate_additive"
            slides = "invert"
            state_bytes = 4
            sum_channels = 3

            def accumulate(self, u, steps, order, step_rgba, spec):
                raise AssertionError

            def finish_sums(self, sums, alpha, positions, spec):
                raise AssertionError

            def finish_kernel(self, acc, positions, spec):
                raise AssertionError

    assert "does not define combine and combine_kernel" in _one_line(exc)


def test_a_mode_comparing_values_needs_leaf_value():
    with pytest.raises(ModeDefinitionError, match=r"compares_values = True \(ComparesValues\)"):

        class NoLeafValue(Mode):
            name = "broken"
            summary = "compares nothing"
            kernel = "extreme"
            kernel_function = "integrate_extreme"
            compares_values = True

            def accumulate(self, u, steps, order, step_rgba, spec):
                raise AssertionError

            def combine(self, front, back, spec):
                raise AssertionError

            def combine_kernel(self, spec):
                raise AssertionError


def _aggregating(**attrs) -> dict:
    """The namespace of an aggregating mode with every hook, changed by `attrs`."""

    def accumulate(self, u, steps, order, step_rgba, spec):
        raise AssertionError

    def combine(self, front, back, spec):
        raise AssertionError

    def combine_kernel(self, spec):
        raise AssertionError

    base = {
        "name": "broken",
        "summary": "a mode",
        "kernel": "alpha",
        "kernel_function": "integrate_alpha",
        "accumulate": accumulate,
        "combine": combine,
        "combine_kernel": combine_kernel,
    }
    return {k: v for k, v in (base | attrs).items() if v is not None}


def test_the_complete_namespace_is_a_mode():
    assert issubclass(type("Fine", (Mode,), _aggregating()), Combines)


@pytest.mark.parametrize(
    ("attrs", "needle"),
    [
        ({"name": None}, "has no name; set it as a class attribute"),
        ({"kernel_function": ""}, "has no kernel_function"),
        ({"accumulate": None}, "does not define accumulate"),
        ({"slides": "slide"}, "sets slides = 'slide'; choose one of aggregate, invert"),
        ({"legend": "steps"}, "sets legend = 'steps'; choose one of time, fraction"),
        ({"pool": "median"}, "sets pool = 'median'; choose one of mean, max, min"),
        ({"reads_values": True}, "sets reads_values = True but its accumulate does not take"),
        ({"sum_channels": 2}, "sets slides = 'aggregate' with sum_channels = 2"),
        ({"rows_kernel": "integrate_alpha_rows"}, "rows_state = 0; a rows kernel needs"),
        ({"rows_state": 16}, "sets rows_kernel = None with rows_state = 16"),
        ({"leaf_span": 0}, "sets leaf_span = 0"),
        ({"writes_winners": True}, "sets writes_winners without has_t_index"),
    ],
)
def test_each_flag_out_of_its_choices_fails_at_class_definition(attrs, needle):
    with pytest.raises(ModeDefinitionError) as exc:
        type("Broken", (Mode,), _aggregating(**attrs))
    text = _one_line(exc)
    assert text.startswith("mode class Broken ") and needle in text, text


def test_accumulate_taking_values_needs_reads_values():
    def accumulate(self, u, steps, order, step_rgba, spec, values):
        raise AssertionError

    with pytest.raises(ModeDefinitionError, match="reads_values = False but its accumulate takes"):
        type("Broken", (Mode,), _aggregating(accumulate=accumulate))
    type("Reads", (Mode,), _aggregating(accumulate=accumulate, reads_values=True))


def test_an_abstract_base_is_unchecked_and_its_modes_are_checked():
    class Family(Mode, abstract=True):  # shared kernel and hooks, no name: not a mode itself
        kernel = "alpha"
        kernel_function = "integrate_alpha"

        def accumulate(self, u, steps, order, step_rgba, spec):
            raise AssertionError

        def combine(self, front, back, spec):
            raise AssertionError

    class Member(Family):
        name = "member"
        summary = "a member"

        def combine_kernel(self, spec):
            raise AssertionError

    assert Member.name == "member"
    with pytest.raises(ModeDefinitionError, match=r"mode class .*Orphan has no name"):

        class Orphan(Family):
            summary = "no name"

            def combine_kernel(self, spec):
                raise AssertionError


def test_a_module_defining_a_broken_mode_fails_to_import(tmp_path):
    """The error comes when the module is imported, before any integration runs."""
    path = tmp_path / "third_party_mode.py"
    path.write_text(
        "from chronocl.modes.base import Mode\n\n\n"
        "class Sums(Mode):\n"
        '    name = "sums"\n'
        '    summary = "sums that never finish"\n'
        '    kernel = "mean"\n'
        '    kernel_function = "integrate_mean"\n'
        '    slides = "invert"\n'
        "    state_bytes = 0\n"
        "    sum_channels = 4\n\n"
        "    def accumulate(self, u, steps, order, step_rgba, spec):\n"
        "        raise AssertionError\n\n"
        "    def finish_sums(self, sums, alpha, positions, spec):\n"
        "        raise AssertionError\n"
    )
    spec = importlib.util.spec_from_file_location("third_party_mode", path)
    module = importlib.util.module_from_spec(spec)
    with pytest.raises(ModeDefinitionError) as exc:
        spec.loader.exec_module(module)
    assert "third_party_mode" not in sys.modules
    assert _one_line(exc) == (
        'mode class Sums sets slides = "invert" (FinishesSums) but does not define '
        "finish_kernel (docs/architecture.md, How to add a mode)"
    )
