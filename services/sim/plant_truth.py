"""The true canopy traits of every plot, computed from the simulated plants themselves
(never from scan points), for the evaluation to score measured traits against.

Each plot's traits are :func:`common.canopy.plot_traits` of all its occupied foliage
voxels, each given by the centres of its four side faces and its top face (the
plant's true extent and top: a ray stops at a voxel's face; heights above the true
terrain), cut to the plot
box's footprint: leaves of plants leaning out of the box are outside the plot, as they are
for the measured traits. The survey-side traits ``points`` and ``seen`` say what a
scanner saw and mean nothing here, so they are left out. Beside them: who the plot is
(index, id, row, column, entry, rep), what its plants were built from (the trial's
:class:`~services.sim.trial.PlotPlan`) and the true extent of its foliage including
the leaning parts (``canopy_xmin``..``canopy_ymax``, ``canopy_top``: voxel faces,
field frame, m), to judge a plan made from a survey.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import msgspec
import numpy as np

from common import fieldbook
from common.arrays import F64
from common.canopy import CanopyDefinition, plot_traits
from common.field import Field, FieldLayout
from common.files import write_atomic
from services.sim.foliage import Foliage
from services.sim.terrain import Terrain
from services.sim.trial import PlotPlan, TrialPlan
from services.sim.truth_file import PLANTS_TRUTH, PlantTruth

if TYPE_CHECKING:
    from services.sim.world import World

# traits that describe a survey's view, not the plants
_SURVEY_ONLY = ("points", "seen")
_PLANNED = (
    "genotype",
    "plants",
    "gaps",
    "leaning",
    "effect_height",
    "effect_width",
    "effect_density",
    "height_m_mature",
    "height_m_planned",
)


def plant_truth(
    layout: FieldLayout,
    field: Field,
    terrain: Terrain,
    foliage: Foliage,
    plan: TrialPlan | None,
    definition: CanopyDefinition | None = None,
) -> list[dict[str, Any]]:
    """One row per plot, in plot order (see the module's docstring); NaN where a plot
    has no canopy, None where a value is not known (an unvaried world's effects)."""
    d = definition or CanopyDefinition()
    recs = fieldbook.records(layout, field)
    rows = []
    for p, rec in enumerate(recs):
        box = field.plot_boxes[p]
        pts, _ = foliage.occupied_points(p)
        faces = _side_faces(pts, foliage.voxel)
        h = faces[:, 2] - terrain.height(faces[:, 0], faces[:, 1])
        inside = (faces[:, 0] >= box[0]) & (faces[:, 0] < box[3])
        inside &= (faces[:, 1] >= box[1]) & (faces[:, 1] < box[4])
        traits = plot_traits(faces[inside, :2], h[inside], box[[0, 1, 3, 4]], d)
        row: dict[str, Any] = {
            "plot": p,
            "plot_id": rec.plot,
            "row": rec.row,
            "column": rec.column,
            "entry": rec.entry,
            "rep": rec.rep,
            "days_after_planting": None if plan is None else plan.days,
        }
        row |= _planned(None if plan is None else plan.plots[p])
        row |= {k: v for k, v in traits.items() if k not in _SURVEY_ONLY}
        row |= _extent(pts, foliage.voxel)
        rows.append(row)
    return rows


def _side_faces(centres: F64, voxel: float) -> F64:
    """The centres of each voxel's four side faces, at its mid-height, and of its top
    face: the plant's true horizontal extent and its true top (a ray stops at a
    voxel's face)."""
    half = voxel / 2
    steps = np.array([[half, 0, 0], [-half, 0, 0], [0, half, 0], [0, -half, 0], [0, 0, half]])
    return (centres[:, None, :] + steps[None, :, :]).reshape(-1, 3)


def _planned(pp: PlotPlan | None) -> dict[str, Any]:
    """What the plot's plants were built from (None: the unvaried plants). ``genotype``:
    the entry whose effects they carry (a plot without an entry is its own)."""
    if pp is None:
        return dict.fromkeys(_PLANNED)
    return {
        "genotype": pp.entry,
        "plants": pp.plants,
        "gaps": pp.gaps,
        "leaning": pp.leaning,
        "effect_height": pp.effects[0],
        "effect_width": pp.effects[1],
        "effect_density": pp.effects[2],
        "height_m_mature": pp.height_m_mature,
        "height_m_planned": pp.height_m,
    }


def _extent(pts: F64, voxel: float) -> dict[str, float]:
    """The faces of the outermost occupied voxels (NaN for an empty plot)."""
    names = ("canopy_xmin", "canopy_ymin", "canopy_xmax", "canopy_ymax", "canopy_top")
    if len(pts) == 0:
        return dict.fromkeys(names, math.nan)
    lo, hi = pts.min(axis=0) - voxel / 2, pts.max(axis=0) + voxel / 2
    vals = (lo[0], lo[1], hi[0], hi[1], hi[2])
    return {k: float(v) for k, v in zip(names, vals, strict=True)}


def plant_truth_of(world: World, definition: CanopyDefinition | None = None) -> PlantTruth:
    """The plants' truth of ``world``."""
    d = definition or CanopyDefinition()
    w, plan = world, world.trial
    return PlantTruth(
        field=w.field.name,
        seed=w.cfg.seed,
        date=w.cfg.trial.date,
        planting_date=w.layout.planting_date,
        days_after_planting=None if plan is None else plan.days,
        trial=w.cfg.trial,
        definition=d,
        plots=plant_truth(w.layout, w.field, w.terrain, w.foliage, plan, d),
    )


def write_plant_truth(folder: Path, world: World) -> Path:
    """Write ``world``'s plant truth as ``folder/`` :data:`PLANTS_TRUTH`, whole or not at
    all; returns its path."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / PLANTS_TRUTH
    write_atomic(path, msgspec.json.encode(plant_truth_of(world)), durable=True)
    return path
