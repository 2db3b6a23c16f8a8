"""The merged LAZ's voxel downsampling keeps exactly the points the row-wise
``np.unique(key, axis=0)`` kept before it was made fast: the first point of every
voxel, in the input order."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from common.geo import rot_zyx
from common.pointcloud import PosedScan, first_per_voxel, voxel_merge
from common.poses import apply

I64 = npt.NDArray[np.int64]


def _rowwise(key: I64) -> I64:
    _, first = np.unique(key, axis=0, return_index=True)
    first.sort()
    return first


@settings(max_examples=200, deadline=None)
@given(
    st.lists(
        st.tuples(st.integers(0, 6), st.integers(0, 6), st.integers(0, 6)),
        min_size=1,
        max_size=300,
    )
)
def test_first_per_voxel_is_the_rowwise_unique(rows: list[tuple[int, int, int]]) -> None:
    key = np.array(rows, dtype=np.int64)
    np.testing.assert_array_equal(first_per_voxel(key), _rowwise(key))


def test_first_per_voxel_of_keys_too_large_to_pack() -> None:
    rng = np.random.default_rng(4)
    key = rng.integers(0, 4, (5000, 3)) * (2**22)  # 2**24 per axis: 2**72 cells
    np.testing.assert_array_equal(first_per_voxel(key), _rowwise(key))


@pytest.mark.parametrize("voxel", [0.0, 0.05, 0.3, 2.0])
def test_voxel_merge_matches_the_rowwise_method(voxel: float) -> None:
    rng = np.random.default_rng(9)
    scans = []
    for k in range(3):
        pose = np.eye(4)
        pose[:3, :3] = rot_zyx(*rng.normal(0, 0.3, 3))
        pose[:3, 3] = rng.uniform(-3, 3, 3)
        pts = rng.uniform(-4, 4, (3000, 3))
        scans.append(PosedScan(pts, rng.uniform(0, 1, 3000).astype(np.float32), pose, f"s{k}"))
    pts, inten, src = voxel_merge(scans, voxel)
    all_pts = np.vstack([apply(s.pose, s.points) for s in scans])
    all_inten = np.concatenate([s.intensity for s in scans])
    keep = np.arange(len(all_pts))
    if voxel > 0:
        keep = _rowwise(np.floor((all_pts - all_pts.min(axis=0)) / voxel).astype(np.int64))
        assert len(keep) < len(all_pts)
    np.testing.assert_array_equal(pts, all_pts[keep])
    np.testing.assert_array_equal(inten, all_inten[keep])
    np.testing.assert_array_equal(src, keep // 3000)
