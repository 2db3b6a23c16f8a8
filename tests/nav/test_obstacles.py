from __future__ import annotations

import math

import numpy as np

from services.nav.obstacles import obstacle_ahead, obstacle_on_leg

ANG = np.radians(np.arange(-135.0, 135.01, 0.25))


def ranges_to(points_body: list[tuple[float, float]]) -> np.ndarray:
    """A scan (lidar at (0.45, 0) in base_link) seeing the given body-frame points."""
    r = np.full(len(ANG), np.inf)
    for x, y in points_body:
        a = math.atan2(y, x - 0.45)
        r[int(np.argmin(np.abs(ANG - a)))] = math.hypot(x - 0.45, y)
    return r


def test_plot_edge_beside_the_lane_is_not_an_obstacle_when_slightly_off() -> None:
    # robot 6 cm right of a lane along +x, yawed 4 deg towards a plot edge 0.4 m right
    yaw = math.radians(-4.0)
    pose = (0.0, -0.06, yaw)
    edge = [(0.6 + 0.05 * k, -0.40) for k in range(12)]  # field frame
    c, s = math.cos(-yaw), math.sin(-yaw)
    body = [
        (c * (x - pose[0]) - s * (y - pose[1]), s * (x - pose[0]) + c * (y - pose[1]))
        for x, y in edge
    ]
    r = ranges_to(body)
    assert obstacle_ahead(r, ANG[0], ANG[1] - ANG[0], (0.45, 0.0, 0.0), 0.495, 0.6, 0.30)
    assert not obstacle_on_leg(
        r, ANG[0], ANG[1] - ANG[0], (0.45, 0.0, 0.0), pose, (-5.0, 0.0, 10.0, 0.0), 0.495, 0.6, 0.30
    )


def test_box_in_the_lane_is_an_obstacle() -> None:
    r = ranges_to([(0.8, y) for y in np.linspace(-0.15, 0.15, 7)])
    assert obstacle_on_leg(
        r,
        ANG[0],
        ANG[1] - ANG[0],
        (0.45, 0.0, 0.0),
        (0.0, 0.0, 0.0),
        (0.0, 0.0, 10.0, 0.0),
        0.495,
        0.6,
        0.30,
    )
