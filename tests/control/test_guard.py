from math import isfinite

from hypothesis import given
from hypothesis import strategies as st

from hexactl.control.guard import guard_setpoints

STROKE = (0.0, 850.0)
STEP = 0.8  # 400 mm/s at 500 Hz

anything = st.floats(allow_nan=True, allow_infinity=True)
inside = st.floats(min_value=STROKE[0], max_value=STROKE[1])


@given(st.lists(anything, min_size=6, max_size=6), st.lists(inside, min_size=6, max_size=6))
def test_output_inside_stroke_and_step_whatever_the_input(desired, previous):
    out, mask = guard_setpoints(desired, previous, STROKE, STEP)
    for i, (value, before) in enumerate(zip(out, previous)):
        assert isfinite(value)
        assert STROKE[0] <= value <= STROKE[1]
        assert abs(value - before) <= STEP * (1 + 1e-12)
        if value != desired[i]:
            assert mask & (1 << i)


def test_reachable_values_pass_untouched():
    previous = [100.0, 200.0, 300.0, 400.0, 500.0, 600.0]
    desired = [p + 0.5 for p in previous]
    assert guard_setpoints(desired, previous, STROKE, STEP) == (desired, 0)


def test_nan_holds_and_out_of_stroke_heads_for_the_limit():
    previous = [0.5, 849.5, 10.0, 10.0, 10.0, 10.0]
    out, mask = guard_setpoints([-5.0, 900.0, float("nan"), 10.0, 10.0, 20.0], previous, STROKE, STEP)
    assert out == [0.0, 850.0, 10.0, 10.0, 10.0, 10.8]
    assert mask == 0b100111


def test_values_on_the_limits_pass_untouched_and_uncounted():
    # On the stroke's ends, and exactly one step up or down (binary-exact numbers): allowed.
    previous = [0.5, 849.5, 10.0, 10.0, 10.0, 10.0]
    desired = [0.0, 850.0, 10.5, 9.5, 10.0, 10.0]
    assert guard_setpoints(desired, previous, STROKE, 0.5) == (desired, 0)


def test_a_jump_either_way_moves_one_full_step_towards_it():
    out, mask = guard_setpoints([20.0, 0.0, 10.0, 10.0, 10.0, 10.0], [10.0] * 6, STROKE, 0.5)
    assert out == [10.5, 9.5, 10.0, 10.0, 10.0, 10.0]
    assert mask == 0b11
