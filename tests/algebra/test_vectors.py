"""Vector helpers against plain loops."""

from __future__ import annotations

import numpy as np
import pytest
from ple.algebra.vectors import runs


@pytest.mark.parametrize("seed", range(5))
def test_runs_are_the_slices_one_after_the_other(seed):
    rng = np.random.default_rng(seed)
    start = rng.integers(0, 100, 30)
    count = rng.integers(0, 5, 30)
    want = [i for s, c in zip(start.tolist(), count.tolist()) for i in range(s, s + c)]
    assert runs(start, count).tolist() == want
    assert runs([], []).tolist() == []
