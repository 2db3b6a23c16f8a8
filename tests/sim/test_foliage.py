import numpy as np
import pytest

from services.sim.foliage import EMPTY, STEM, build_foliage
from services.sim.plant_config import FoliageConfig
from services.sim.scene import LEAF_HIT, STEM_HIT, Scene
from services.sim.terrain import TerrainConfig, build_terrain

BOXES = np.array([[2.0, 1.0, 0.0, 5.0, 2.0, 1.9], [7.0, 1.0, 0.0, 10.0, 2.0, 1.9]])


@pytest.fixture(scope="module")
def world():
    ter = build_terrain(np.array([0.0, 0.0, 12.0, 3.0]), TerrainConfig(margin=2.0), seed=0)
    return ter, build_foliage(BOXES, ter, FoliageConfig(), seed=0)


def test_foliage_stays_inside_its_plot(world):
    ter, fol = world
    for p, box in enumerate(BOXES):
        pts, vals = fol.occupied_points(p)
        assert len(pts) > 1000
        v = fol.voxel
        assert np.all(pts[:, 0] >= box[0]) and np.all(pts[:, 0] <= box[3])
        assert np.all(pts[:, 1] >= box[1]) and np.all(pts[:, 1] <= box[4])
        above = pts[:, 2] - ter.height(pts[:, 0], pts[:, 1])
        assert above.max() <= box[5] + v and above.min() >= -2 * v
        assert (vals == STEM).any() and (vals != STEM).sum() > (vals == STEM).sum()


def test_foliage_is_not_solid(world):
    _, fol = world
    g = fol.grid(0)
    fill = (g != EMPTY).mean()
    assert 0.03 < fill < 0.4
    # horizontal rays across the row get into the canopy before being stopped
    scene = Scene(None, fol, np.zeros((0, 5)), np.zeros((0, 6)), np.zeros((0, 7)))
    xs = np.linspace(2.3, 4.7, 200)
    depth = []
    for x in xs:
        t, lab, _ = scene.cast([x, 0.5, 0.9], np.array([[0.0, 1.0, 0.0]]), 3.0)
        if np.isfinite(t[0]):
            assert lab[0] in (LEAF_HIT, STEM_HIT)
            depth.append(t[0] - 0.5)
    assert len(depth) > 150  # a mature canopy stops most rays across 1 m...
    assert np.median(depth) > 0.1  # ...but not at its face


def test_foliage_is_seeded_per_plot(world):
    ter, fol = world
    again = build_foliage(BOXES[:1], ter, FoliageConfig(), seed=0)
    np.testing.assert_array_equal(again.grid(0), fol.grid(0))
    other = build_foliage(BOXES[:1], ter, FoliageConfig(), seed=1)
    assert not np.array_equal(other.grid(0), fol.grid(0))


def test_bad_boxes_are_rejected(world):
    ter, _ = world
    with pytest.raises(ValueError, match="plot_boxes"):
        build_foliage(np.array([[1.0, 1, 0, 0, 2, 1]]), ter, FoliageConfig(), seed=0)
