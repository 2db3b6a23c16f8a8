import math

import numpy as np

from common.robot import default_robot
from services.sim.lidar import LidarConfig, beam_angles, scan
from services.sim.robot import RobotState
from services.sim.scene import OBSTACLE, Scene

CFG = LidarConfig()


def _scene(boxes):
    return Scene(None, None, np.zeros((0, 5)), np.zeros((0, 6)), np.asarray(boxes, float))


def test_box_two_metres_ahead():
    lx = default_robot().lidar.x
    box = [[lx + 2.0, -0.5, -1.0, lx + 2.5, 0.5, 2.0, OBSTACLE]]
    r = scan(_scene(box), RobotState(), CFG, np.random.default_rng(0))
    a = beam_angles(CFG)
    assert len(r) == 1081 and r.dtype == np.float32
    zero = int(np.argmin(np.abs(a)))
    assert abs(a[zero]) < 1e-12
    assert abs(r[zero] - 2.0) < 0.1
    # beams that miss the box see nothing within 5 m
    assert np.all(np.isinf(r[np.abs(a) > math.radians(30)]))


def test_rotated_robot_and_range_limit():
    lx = default_robot().lidar.x
    box = [[-0.5, lx + 2.0, -1.0, 0.5, lx + 2.5, 2.0, OBSTACLE]]
    r = scan(_scene(box), RobotState(yaw=math.pi / 2), CFG, np.random.default_rng(0))
    assert abs(r[540] - 2.0) < 0.1
    far = [[lx + 6.0, -0.5, -1.0, lx + 7.0, 0.5, 2.0, OBSTACLE]]
    assert np.isinf(scan(_scene(far), RobotState(), CFG, np.random.default_rng(0))[540])
