"""Planning on the crop as a survey measured it (:mod:`common.cropmodel`): each plot's
box becomes its measured canopy box (a plant leaning into a lane widens it, so the lane
and the candidate clearance follow), and only cells over columns that hold canopy are
to be seen (a gap, where plants failed to emerge, has nothing to scan).

A plot without canopy keeps its nominal footprint, 5 cm tall (:data:`BARE_HEIGHT`),
with no cell to cover: dropping it would renumber the plots against the field book and
could empty a row, which the lanes are built from; at 5 cm it hides next to nothing.
"""

from __future__ import annotations

from pathlib import Path

import msgspec
import numpy as np
import numpy.typing as npt

from common import cropmodel
from common.arrays import F64
from common.cropmodel import CropModel, CropModelError
from common.field import Field, FieldError, FieldLayout, ScannerModel, assemble
from common.messages.core import Array
from common.messages.plan import PlanOptions, PlanRequest, PlanResult
from services.planner.budget import PlanBudget, check
from services.planner.core import plan
from services.planner.request import resolve_field
from services.planner.visibility import Progress

Mask = npt.NDArray[np.bool_]

BARE_HEIGHT = 0.05  # m, a plot without canopy: the canopy threshold's height
MIN_SIDE = 0.1  # m, a measured footprint narrower than this (a lone plant) is widened
CROP_FILE = "crop.json"


def measured_boxes(field: Field, model: CropModel) -> F64:
    """(P, 6) boxes of the crop as measured: xy extent and height of each plot's canopy
    (zmin 0), nominal footprint at :data:`BARE_HEIGHT` for a plot without canopy."""
    cropmodel.check(model, field)
    m = model.boxes()
    boxes = field.plot_boxes.copy()
    boxes[:, 2] = 0.0
    boxes[:, 5] = BARE_HEIGHT
    have = np.isfinite(m[:, 0])
    lo, hi = m[have, 0:2], m[have, 2:4]
    # a lone plant's footprint is a point: give it some width so it has cells
    mid, half = (lo + hi) / 2, np.maximum((hi - lo) / 2, MIN_SIDE / 2)
    boxes[have, 0:2], boxes[have, 3:5] = mid - half, mid + half
    boxes[have, 5] = np.maximum(m[have, 4], BARE_HEIGHT)
    return boxes


def measured_field(
    layout: FieldLayout, field: Field, model: CropModel
) -> tuple[FieldLayout, Field]:
    """The field as measured (same layout, plots, rows and columns; lanes and candidates
    from the measured boxes). Raises CropModelError when the model is of another field
    or the measured plots of two rows (or columns) overlap."""
    boxes = measured_boxes(field, model)
    try:
        fld = assemble(layout, boxes, field.plot_row, field.plot_col, field.bounds)
    except FieldError as exc:
        raise CropModelError(f"the measured crop of field {field.name!r}: {exc}") from None
    return layout, fld


def target_cells(nominal: Field, measured: Field, model: CropModel) -> Mask:
    """A flag per cell of ``measured``: to be seen. A cell is a target when the nominal
    column under its centre holds canopy, or when its centre lies outside the nominal
    footprint (canopy leaning into a lane, which the measured box holds only because
    canopy was there); a plot without canopy has none."""
    cropmodel.check(model, nominal)
    cb = measured.cell_boxes
    p = measured.cell_plot
    cx, cy = (cb[:, 0] + cb[:, 3]) / 2, (cb[:, 1] + cb[:, 4]) / 2
    nb = nominal.plot_boxes[p]
    nx, ny = nominal.cell_dims[p, 0], nominal.cell_dims[p, 1]
    fx = (cx - nb[:, 0]) / (nb[:, 3] - nb[:, 0])
    fy = (cy - nb[:, 1]) / (nb[:, 4] - nb[:, 1])
    inside = (fx >= 0) & (fx < 1) & (fy >= 0) & (fy < 1)
    ix = np.clip((fx * nx).astype(np.int64), 0, nx - 1)
    iy = np.clip((fy * ny).astype(np.int64), 0, ny - 1)
    per_plot = nominal.cell_dims[:, 0] * nominal.cell_dims[:, 1]
    offset = np.concatenate([[0], np.cumsum(per_plot)])
    occupied = np.zeros(int(offset[-1]), dtype=bool)
    for q, pc in enumerate(model.plots):
        occupied[offset[q] + np.array(pc.columns, dtype=np.int64)] = True
    has_canopy = np.array([pc.box is not None for pc in model.plots], dtype=bool)
    return has_canopy[p] & np.where(inside, occupied[offset[p] + ix * ny + iy], True)


def plan_measured(
    layout: FieldLayout,
    field: Field,
    model: CropModel,
    scanner: ScannerModel | None = None,
    options: PlanOptions | None = None,
    progress: Progress | None = None,
) -> PlanResult:
    """Plan on the measured field, covering its target cells; the plan keeps the
    field's plot boxes as its ``footprints`` (what the survey's traits are cut by).
    Raises CropModelError or ValueError (one line)."""
    _, fld = measured_field(layout, field, model)
    targets = target_cells(field, fld, model)
    if not targets.any():
        raise CropModelError(f"the crop model of field {field.name!r} holds no canopy")
    result = plan(layout, scanner, options, field=fld, progress=progress, targets=targets)
    return msgspec.structs.replace(result, footprints=Array.of(field.plot_boxes))


def plan_from_survey(
    req: PlanRequest, run_dir: Path, progress: Progress | None = None
) -> tuple[PlanResult, PlanResult]:
    """The plans on the nominal and on the measured field of ``req``'s field, the crop
    read from ``run_dir/crop.json``. Raises FieldError or CropModelError (one line)."""
    layout, fld = resolve_field(req)
    path = Path(run_dir) / CROP_FILE
    if not path.is_file():
        raise CropModelError(f"{path}: no crop model; run `phenorover traits {run_dir}` first")
    model = cropmodel.read(path, fld)
    check(fld, PlanBudget(), req.scanner.max_range)
    nominal = plan(layout, req.scanner, req.options, field=fld, progress=progress)
    measured = plan_measured(layout, fld, model, req.scanner, req.options, progress)
    return nominal, measured


def compare(nominal: PlanResult, measured: PlanResult) -> str:
    """How the plan on the measured crop differs from the nominal one, in lines."""
    a, b = set(nominal.selected), set(measured.selected)

    def ids(s: set[int]) -> str:
        return f"{len(s)}" + (f" ({', '.join(str(i) for i in sorted(s))})" if s else "")

    def cover(r: PlanResult) -> str:
        c = r.cover
        return (
            f"{c.count} locations, {c.cells_covered}/{c.cells_total} target cells covered "
            f"({c.cells_coverable} coverable), tour {r.tour.length:.1f} m"
        )

    rows = [
        ("nominal", cover(nominal)),
        ("measured", cover(measured)),
        ("kept", ids(a & b)),
        ("added", ids(b - a)),
        ("removed", ids(a - b)),
    ]
    w = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{w}}  {v}" for k, v in rows)
