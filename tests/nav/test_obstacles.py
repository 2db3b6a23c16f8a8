from __future__ import annotations

import math

import numpy as np

from services.nav.obstacles import ObstacleWatch, hits_ahead, hits_on_leg

ANG = np.radians(np.arange(-135.0, 135.01, 0.25))
INC = float(ANG[1] - ANG[0])
LIDAR = (0.45, 0.0, 0.0)  # in base_link
FRONT = 0.495  # the robot's front, base_link x


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
    assert len(hits_ahead(r, ANG[0], INC, LIDAR, FRONT, 0.6, 0.30)) >= 3
    leg = (-5.0, 0.0, 10.0, 0.0)
    assert len(hits_on_leg(r, ANG[0], INC, LIDAR, pose, leg, FRONT, 0.6, 0.30)) == 0


def test_box_in_the_lane_is_an_obstacle_and_its_returns_are_in_the_field_frame() -> None:
    r = ranges_to([(0.8, y) for y in np.linspace(-0.15, 0.15, 7)])
    pose = (2.0, 1.0, 0.0)
    hits = hits_on_leg(r, ANG[0], INC, LIDAR, pose, (0.0, 1.0, 10.0, 1.0), FRONT, 0.6, 0.30)
    assert len(hits) == 7
    assert np.allclose(hits[:, 0], 2.8, atol=0.01)
    assert np.all(np.abs(hits[:, 1] - 1.0) <= 0.16)


def test_what_lies_beyond_the_legs_end_is_not_on_the_leg() -> None:
    # 0.2 m before the leg's end: a plot 0.6 m ahead of the front is past where the
    # front will stop, so it does not hold the robot up; 0.1 m ahead of it, it does
    pose = (9.8, 0.0, 0.0)
    leg = (0.0, 0.0, 10.0, 0.0)
    far = ranges_to([(FRONT + 0.5, y) for y in np.linspace(-0.1, 0.1, 5)])
    near = ranges_to([(FRONT + 0.1, y) for y in np.linspace(-0.1, 0.1, 5)])
    assert len(hits_on_leg(far, ANG[0], INC, LIDAR, pose, leg, FRONT, 0.6, 0.30)) == 0
    assert len(hits_on_leg(near, ANG[0], INC, LIDAR, pose, leg, FRONT, 0.6, 0.30)) == 5
    # the body-aligned box knows no leg and sees both
    assert len(hits_ahead(far, ANG[0], INC, LIDAR, FRONT, 0.6, 0.30)) == 5


def test_the_watch_holds_and_frees_after_consecutive_scans_and_says_where() -> None:
    watch = ObstacleWatch(min_points=3, scans=2)
    box, none = np.array([[1.0, -0.1], [1.1, 0.0], [1.2, 0.1]]), np.empty((0, 2))
    assert watch.update(0.0, box, "field") is None  # one scan is not enough
    assert watch.update(0.1, box[:2], "field") is None  # too few returns: the run restarts
    assert watch.update(0.2, box, "field") is None and not watch.held
    said = watch.update(0.3, box, "field")
    assert watch.held and said is not None and "x 1.00..1.20" in said and "y -0.10..0.10" in said
    assert watch.update(0.4, box, "field") is None  # still held: said once
    assert watch.update(0.5, none, "field") is None and watch.held  # one clear scan
    assert watch.update(0.6, none, "field") == "obstacle: the box ahead is clear"
    assert not watch.held


def test_an_obstacle_that_comes_and_goes_is_said_once_in_a_while() -> None:
    watch = ObstacleWatch(min_points=1, scans=1, quiet_s=10.0)
    box, none = np.array([[1.0, 0.0]]), np.empty((0, 2))
    said = [watch.update(0.1 * k, box if k % 2 == 0 else none, "field") for k in range(100)]
    holds = [s for s in said if s is not None and "returns" in s]
    assert len(holds) == 1  # 10 s of flapping: one line, and its end
    assert said.count("obstacle: the box ahead is clear") == 1
    assert watch.update(10.0, box, "field") is not None  # the quiet time is over


def test_the_crop_at_the_lanes_edge_is_not_an_obstacle_but_a_box_in_the_lane_is() -> None:
    # lane along y = 19 (-x), plot below it up to y = 18.6; the estimate 10 cm off puts
    # the plot's edge 0.30 m from the lane's centre, inside the box
    pose = (26.9, 19.0, math.pi)
    leg = (28.5, 19.0, 1.5, 19.0)
    plot = np.array([[24.75, 17.6, 27.75, 18.6]])
    crop = plot + np.array([-0.15, -0.15, 0.15, 0.15])
    edge = [(0.6 + 0.05 * k, 0.299) for k in range(12)]  # body frame: on the left
    r = ranges_to(edge)
    assert len(hits_on_leg(r, ANG[0], INC, LIDAR, pose, leg, FRONT, 0.6, 0.30)) >= 3
    assert len(hits_on_leg(r, ANG[0], INC, LIDAR, pose, leg, FRONT, 0.6, 0.30, crop)) == 0
    person = ranges_to([(0.8, y) for y in np.linspace(-0.1, 0.1, 5)])
    assert len(hits_on_leg(person, ANG[0], INC, LIDAR, pose, leg, FRONT, 0.6, 0.30, crop)) == 5
