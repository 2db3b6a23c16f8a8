"""The field cells a plan's view counts belong to, for the dashboard (the plan's field
file is read)."""

from __future__ import annotations

import contextlib

import numpy as np

from common.arrays import I64
from common.field import Field, FieldError, build_field, load_field
from common.messages.plan import PlanResult
from services.viz import scene


def plan_cells(plan: PlanResult) -> tuple[Field | None, I64 | None, str]:
    """(the field of ``plan``'s plots, its cells' view counts, why not): the field is
    built from the plan's layout or read from its field file, whichever has its
    plots; the counts are None (and the reason said) when the plan has none or they
    are not that field's cells."""
    candidates = []
    with contextlib.suppress(FieldError):
        candidates.append(build_field(plan.layout))
    with contextlib.suppress(FieldError):
        candidates.append(load_field(plan.field)[1])
    field = scene.field_of(plan, candidates)
    if field is None or plan.cell_views is None:
        return field, None, f"plan {plan.field}: field cells not known here, plots only"
    views = np.asarray(plan.cell_views.numpy(), dtype=np.int64)
    if len(views) != len(field.cell_boxes):
        return field, None, f"plan {plan.field}: cells differ from the field's, plots only"
    return field, views, ""
