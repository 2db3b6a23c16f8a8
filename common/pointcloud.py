"""Point cloud files: multi-scan E57 with poses, and merged LAZ (pye57, laspy), for
registration (which writes them) and the dashboard (which reads them).

An E57 keeps every scan as its own data3D entry, points in the scanner frame
(as measured) with the registration's pose as the scan's E57 pose (rotation
quaternion w, x, y, z and translation, ``field <- scanner``): CloudCompare and FARO
SCENE apply the pose on import, so the scans open registered and can still be
re-registered. pye57 appends one data3D entry per ``write_scan_raw`` call.

The LAZ holds all scans merged in the ``field`` frame (or UTM when a transform is
given), voxel-downsampled, with intensity scaled to 0-65535 and the scan index as
``point_source_id``. Coordinates are stored as integers with a 1 mm scale (LAS
scale 0.001) and an offset at the cloud's minimum rounded to 1 km, which keeps mm
precision for UTM northings in the millions.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation

from common.arrays import F32
from common.files import atomic_path
from common.poses import F64, apply, check_pose

# (x, y, z) field -> (east, north, up) UTM, arrays in and out
UtmFn = Callable[[F64, F64, F64], tuple[npt.ArrayLike, npt.ArrayLike, npt.ArrayLike]]


class CloudIOError(ValueError):
    """A point cloud file that cannot be written or read as asked (one line naming it)."""


@dataclasses.dataclass(frozen=True, eq=False)
class PosedScan:
    """One scan: points (N, 3) in its scanner frame, intensity (N,) in [0, 1], pose
    (4x4 field <- scanner) and name."""

    points: F64
    intensity: F32
    pose: F64
    name: str

    @classmethod
    def as_scanned(cls, points: npt.ArrayLike, intensity: npt.ArrayLike, name: str) -> PosedScan:
        """A scan as the scanner writes it to its card: in its own frame, no pose."""
        pts = np.asarray(points, dtype=np.float64)
        return cls(pts, np.asarray(intensity, dtype=np.float32), np.eye(4), name)


def write_e57(path: str | Path, scans: Sequence[PosedScan], durable: bool = False) -> None:
    """Write all ``scans`` to one E57 file, each with its pose (one data3D entry per
    scan), whole or not at all (:func:`common.files.atomic_path`; ``durable``: synced
    to disk, as a scanner's card is). pye57 stores coordinates as 32-bit floats (about
    4 um at 70 m). Raises CloudIOError naming the scan with bad data."""
    import pye57

    if not scans:
        raise CloudIOError(f"{path}: no scans to write")
    for s in scans:
        if s.points.ndim != 2 or s.points.shape[1] != 3 or len(s.points) != len(s.intensity):
            raise CloudIOError(
                f"{path}: scan {s.name!r}: points {s.points.shape} and intensity "
                f"{s.intensity.shape} do not match"
            )
        if len(s.points) == 0:
            raise CloudIOError(f"{path}: scan {s.name!r} has no points")
        check_pose(s.pose, f"{path}: scan {s.name!r} pose")
    with atomic_path(Path(path), durable) as tmp:
        e57 = pye57.E57(str(tmp), mode="w")
        try:
            for s in scans:
                q = Rotation.from_matrix(s.pose[:3, :3]).as_quat()  # x, y, z, w
                wxyz = np.array([q[3], q[0], q[1], q[2]]) * (1.0 if q[3] >= 0 else -1.0)
                data = {
                    "cartesianX": np.ascontiguousarray(s.points[:, 0], dtype=np.float64),
                    "cartesianY": np.ascontiguousarray(s.points[:, 1], dtype=np.float64),
                    "cartesianZ": np.ascontiguousarray(s.points[:, 2], dtype=np.float64),
                    "intensity": np.asarray(s.intensity, dtype=np.float64),
                }
                e57.write_scan_raw(data, name=s.name, rotation=wxyz, translation=s.pose[:3, 3])
        finally:
            e57.close()


def _open_e57(path: str | Path) -> Any:
    """``path`` opened for reading (a ``pye57.E57``); raises CloudIOError."""
    import pye57

    try:
        return pye57.E57(str(path), mode="r")
    except Exception as exc:  # libE57 raises its own exception types
        raise CloudIOError(f"{path}: cannot read E57: {exc}") from None


def read_e57(path: str | Path) -> list[PosedScan]:
    """Every scan of an E57 file with its pose (identity when it has none). Raises
    CloudIOError when the file cannot be read."""
    e57 = _open_e57(path)
    out = []
    try:
        for i in range(e57.scan_count):
            raw = e57.read_scan_raw(i, ignore_unsupported_fields=True)
            header = e57.get_header(i)
            pose = np.eye(4)
            if header.has_pose():
                pose[:3, :3] = header.rotation_matrix
                pose[:3, 3] = header.translation
            pts = np.column_stack([raw["cartesianX"], raw["cartesianY"], raw["cartesianZ"]])
            inten = np.asarray(raw.get("intensity", np.zeros(len(pts))), dtype=np.float32)
            out.append(PosedScan(pts.astype(np.float64), inten, pose, str(header["name"].value())))
    finally:
        e57.close()
    return out


def read_e57_positions(path: str | Path) -> F64:
    """The (S, 3) positions of the scanner at every scan of an E57 file (its poses'
    translations; NaN for a scan without a pose), without reading the points. Raises
    CloudIOError when the file cannot be read."""
    e57 = _open_e57(path)
    try:
        out = np.full((e57.scan_count, 3), np.nan)
        for i in range(e57.scan_count):
            header = e57.get_header(i)
            if header.has_pose():
                out[i] = header.translation
    finally:
        e57.close()
    return out


Merged = tuple[F64, F32, npt.NDArray[np.int64]]


def voxel_merge(scans: Sequence[PosedScan], voxel: float) -> Merged:
    """All scans in the field frame, keeping the first point of every ``voxel`` cube
    (m; 0 keeps all): points (N, 3), intensity (N,), scan index (N,)."""
    pts = np.vstack([apply(s.pose, s.points) for s in scans])
    inten = np.concatenate([s.intensity for s in scans]).astype(np.float32)
    src = np.concatenate([np.full(len(s.points), k) for k, s in enumerate(scans)]).astype(np.int64)
    if voxel > 0 and len(pts):
        first = first_per_voxel(np.floor((pts - pts.min(axis=0)) / voxel).astype(np.int64))
        pts, inten, src = pts[first], inten[first], src[first]
    return pts, inten, src


def first_per_voxel(key: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
    """Ascending indices of the first row of every distinct row of ``key`` (N, 3),
    non-negative voxel indices: ``np.unique(key, axis=0, return_index=True)``, sorted."""
    dims = [int(v) + 1 for v in key.max(axis=0)]
    if dims[0] * dims[1] * dims[2] < 2**63:
        # rows as one integer, in the rows' lexicographic order: unique on a 1-D array
        # sorts integers, ten times faster than the rows compared field by field
        flat = (key[:, 0] * dims[1] + key[:, 1]) * dims[2] + key[:, 2]
        _, first = np.unique(flat, return_index=True)
    else:  # a cloud kilometres across at a millimetre
        _, first = np.unique(key, axis=0, return_index=True)
    first.sort()
    out: npt.NDArray[np.int64] = first.astype(np.int64, copy=False)
    return out


def write_laz(
    path: str | Path,
    scans: Sequence[PosedScan],
    voxel: float = 0.01,
    to_utm: UtmFn | None = None,
    epsg: int | None = None,
) -> int:
    """Write the merged, voxel-downsampled cloud (field frame, or UTM through
    ``to_utm``; ``epsg`` recorded as the CRS when given) to a LAZ (or LAS, by the
    suffix) file; returns the number of points written."""
    return write_merged_laz(path, voxel_merge(scans, voxel), to_utm, epsg)


def write_merged_laz(
    path: str | Path, merged: Merged, to_utm: UtmFn | None = None, epsg: int | None = None
) -> int:
    """:func:`write_laz` of a cloud already merged by :func:`voxel_merge` (to write it
    in more than one frame without merging it again), whole or not at all
    (:func:`common.files.atomic_path`)."""
    import laspy

    pts, inten, src = merged
    if len(pts) == 0:
        raise CloudIOError(f"{path}: no points to write")
    if to_utm is not None:
        e, n, u = to_utm(pts[:, 0], pts[:, 1], pts[:, 2])
        pts = np.column_stack([np.asarray(e), np.asarray(n), np.asarray(u)]).astype(np.float64)
    header = laspy.LasHeader(point_format=1, version="1.4")
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = np.floor(pts.min(axis=0) / 1000.0) * 1000.0
    if epsg is not None:
        from pyproj import CRS

        header.add_crs(CRS.from_epsg(epsg))
    las = laspy.LasData(header)
    las.x, las.y, las.z = pts[:, 0], pts[:, 1], pts[:, 2]
    las.intensity = np.clip(inten * 65535.0, 0, 65535).astype(np.uint16)
    las.point_source_id = src.astype(np.uint16)
    with atomic_path(Path(path)) as tmp:
        las.write(str(tmp))
    return len(pts)
