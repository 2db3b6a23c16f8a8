"""The experiments' pure statistics."""

from __future__ import annotations

import numpy as np
import pytest

from phenorover.eval.experiments import path_length


def test_the_distance_driven_is_the_length_of_the_path_driven() -> None:
    xy = np.array([[0.0, 0.0], [3.0, 4.0], [3.0, 4.0], [3.0, 0.0]])
    assert path_length(xy) == pytest.approx(9.0)  # standing still adds nothing
    assert path_length(xy[:1]) == 0.0
    assert path_length(np.empty((0, 2))) == 0.0
