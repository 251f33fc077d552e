"""testcases/pairing.py: each frame paired with the other message's frame of the same cycle."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from testcases.pairing import nearest, nearest_values


def test_a_step_is_not_interpolated() -> None:
    """The case CI failed on: the rear wheel's frames come 0.9 ms after the front wheel's; at the step the front's
    frame pairs with the rear's frame of the same cycle, not with a mix of the two cycles."""
    front_t = np.array([0.000, 0.010, 0.020])
    rear_t, rear = front_t + 0.0009, np.array([0.0, 1.6, 1.6])
    assert np.interp(front_t, rear_t, rear)[1] < 1.6          # what the cases did before
    assert nearest_values(front_t, rear_t, rear).tolist() == [0.0, 1.6, 1.6]


def test_window_and_ties() -> None:
    index, ok = nearest(np.array([0.005, 0.0101, 0.05]), np.array([0.0, 0.01, 0.02]), window=0.004)
    assert index.tolist() == [0, 1, 2] and ok.tolist() == [False, True, False]   # 0.005: a tie, the earlier


def test_no_frames_is_nan() -> None:
    assert np.isnan(nearest_values(np.array([1.0, 2.0]), np.array([]), np.array([]))).all()


@given(st.lists(st.floats(0, 100, allow_nan=False), min_size=1, max_size=30, unique=True),
       st.lists(st.floats(-10, 110, allow_nan=False), min_size=1, max_size=30))
def test_nearest_is_the_closest_frame(times: list[float], queries: list[float]) -> None:
    """Against a brute-force search: no frame is nearer than the one chosen."""
    ts, q = np.array(sorted(times)), np.array(queries)
    index, _ = nearest(q, ts)
    for i, t in zip(index, q):
        assert abs(ts[i] - t) == np.min(np.abs(ts - t))
