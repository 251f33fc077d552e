"""Pairing frames of different messages by receive time: each frame of one message with the frame of another that
is nearest to it in time.

On the virtual bus the frames of one instant share one timestamp; on a real-time bus (vcan, hardware) they arrive
a fraction of a millisecond apart, in any order. Interpolating the other message at the first one's times then
mixes in the previous cycle's value, which after a step is a value nobody sent; taking the nearest frame takes
the one of the same cycle.
"""

from __future__ import annotations

import numpy as np


def nearest(t: np.ndarray, times: np.ndarray, window: float = np.inf) -> tuple[np.ndarray, np.ndarray]:
    """(index into `times` of the frame nearest to each of `t`, whether it is at most `window` s away).

    `times` ascending and not empty; a tie goes to the earlier frame."""
    last = times.size - 1
    before = np.clip(np.searchsorted(times, t, side="right") - 1, 0, last)
    after = np.clip(before + 1, 0, last)
    gap_before, gap_after = np.abs(t - times[before]), np.abs(times[after] - t)
    index = np.where(gap_after < gap_before, after, before)
    return index, np.minimum(gap_before, gap_after) <= window


def nearest_values(t: np.ndarray, times: np.ndarray, values: np.ndarray) -> np.ndarray:
    """The value of the frame nearest to each of `t` (NaN for all of them when there is no frame)."""
    if times.size == 0:
        return np.full(np.shape(t), np.nan)
    index, _ = nearest(t, times)
    return values[index]
