"""Multiple shooting over drive cycles, by translation: each experiment's record is cut into
segments that start just before each fast edge (where the main body has stuck through the slow
phase), and each segment is compared with the model after its own best translation (a position
offset). The model's trajectory is carried across segments (its velocities, friction and
hysteresis states), but a position error made in one cycle — one slip event more or less — is
reconciled at the next segment's start instead of shifting every later cycle. The IDM's
dynamics are translation invariant (only a ground spring depends on absolute position), so this
is exactly multiple shooting with each segment's start position re-estimated from the data, at
the price of one offset per segment and no extra simulation. The misfit becomes a smooth
function of the parameters over the whole record (one cycle's worth of jump at most where a
slip event appears or vanishes), which is what a global calibration needs."""

from __future__ import annotations

from ..io.recording import Experiment


def segment_starts(e: Experiment, sample_rate_Hz: float, n_samples: int) -> list[int]:
    """Sample indices where the segments of experiment `e` start (the first is 0), within its
    first `n_samples` samples: one before every fast edge but the first. A sampled drive has no
    cycles to cut at: one segment."""
    if e.is_sampled:
        return [0]
    period = 1.0 / e.frequency_Hz
    # the fast edge of cycle k: at its start (forward) or its end (backward)
    edge_at = 0.0 if e.direction == "forward" else period - e.edge_s
    starts = [0]
    for k in range(1, e.cycles):
        t = e.rest_s + k * period + edge_at
        i = int(round(t * sample_rate_Hz))
        if 0 < i < n_samples - 2:
            starts.append(i)
    return starts
