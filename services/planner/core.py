"""The planning pipeline: field -> visibility -> set cover -> tour -> legs. Pure: no
I/O beyond logging; every stage is timed."""

from __future__ import annotations

import logging
import time

import msgspec
import numpy as np
import numpy.typing as npt
import scipy.sparse as sp

from common.arrays import F64
from common.battery import Battery
from common.field import Field, FieldLayout, ScannerModel, build_field
from common.messages.core import Array
from common.messages.nav import Leg
from common.messages.plan import (
    Candidate,
    CoverSummary,
    Fleet,
    PlanOptions,
    PlanResult,
    TourSummary,
    VisibilitySummary,
)
from services.planner.cover import Cover, exact_cover, greedy_cover
from services.planner.fleet import fleet
from services.planner.route import Navigator
from services.planner.swaps import survey_estimate, via_origin
from services.planner.tsp import (
    nearest_neighbour,
    one_tree_bound,
    solve_tour,
)
from services.planner.visibility import Chunks, Progress, compute_visibility
from services.planner.waypoints import tour_legs

log = logging.getLogger(__name__)


def _cover_summary(c: Cover, method: str, greedy_count: int) -> CoverSummary:
    return CoverSummary(
        method=method,
        count=len(c.selected),
        greedy_count=greedy_count,
        cells_total=c.cells_total,
        cells_coverable=c.cells_coverable,
        cells_target=c.cells_target,
        cells_covered=c.cells_covered,
        status=c.status,
        bound=None if np.isnan(c.bound) else c.bound,
        gap=None if np.isnan(c.gap) else c.gap,
        time_s=c.time_s,
    )


def plan(
    layout: FieldLayout,
    scanner: ScannerModel | None = None,
    options: PlanOptions | None = None,
    *,
    field: Field | None = None,
    progress: Progress | None = None,
    targets: npt.NDArray[np.bool_] | None = None,
    chunks: Chunks | None = None,
    battery: Battery | None = None,
) -> PlanResult:
    """Plan a survey of ``layout`` (or of ``field`` when given, e.g. one loaded from
    GeoJSON). ``progress(done, total)`` follows the visibility stage. ``targets``: a
    flag per cell of the field, the cells to cover (None: all; e.g. no gaps in a
    measured crop); the others still occlude. ``chunks``: where the visibility's chunks
    are cast (:func:`.visibility.compute_visibility`). ``battery``: the robot's (default:
    the Husky's), for the survey's swaps. Raises ValueError on inconsistent options
    (such as a lane index outside the field)."""
    scanner = scanner or ScannerModel()
    opt = options or PlanOptions()
    battery = battery or Battery()
    timings: dict[str, float] = {}
    t = time.perf_counter()
    fld = field if field is not None else build_field(layout)
    if targets is not None and targets.shape != (fld.n_cells,):
        raise ValueError(f"targets: {targets.shape} flags for {fld.n_cells} cells")
    nav = Navigator(fld, opt.nav, opt.open_rows, opt.open_cross)
    timings["field"] = time.perf_counter() - t

    # the cover, and every count of cells, only over the target cells (mat)
    every, mat, vsum = _visibility(fld, scanner, opt, progress, chunks, targets)
    timings["visibility"] = vsum.time_s
    seen = np.asarray(mat.sum(axis=1)).ravel()

    t = time.perf_counter()
    cover, greedy_count = _cover(mat, opt)
    timings["cover"] = time.perf_counter() - t

    t = time.perf_counter()
    sel = list(cover.selected)
    pts = np.vstack([fld.origin_xy[None, :], fld.cand_xy[sel]])
    ids: list[int | None] = [None, *(int(fld.cand_ids[j]) for j in sel)]
    order, tour = _tour(nav, opt, pts, ids, t)
    timings["tour"] = tour.time_s

    t = time.perf_counter()
    legs = tour_legs(nav, pts, order, ids)
    via = via_origin(nav, pts[0], pts[1:], [int(i or 0) for i in ids[1:]])
    survey = survey_estimate(legs, via, battery, opt.pace)
    timings["legs"] = time.perf_counter() - t
    shares = None
    if opt.robots > 1 or opt.home == "near":
        t = time.perf_counter()
        shares = _fleet(nav, pts, ids, via, battery, opt, survey.time_s)
        timings["fleet"] = time.perf_counter() - t
    return PlanResult(
        field=fld.name,
        layout=layout,
        scanner=scanner,
        options=opt,
        origin=(float(fld.origin_xy[0]), float(fld.origin_xy[1])),
        plot_boxes=Array.of(fld.plot_boxes),
        candidates=_candidates(fld, seen),
        selected=[int(fld.cand_ids[j]) for j in sel],
        visibility=vsum,
        cover=_cover_summary(cover, opt.cover, greedy_count),
        tour=tour,
        legs=legs,
        timings=timings,
        cell_views=Array.of(np.asarray(every[sel].sum(axis=0), dtype=np.int64).ravel()),
        via_origin=via,
        survey=survey,
        fleet=shares,
    )


def _cover(mat: sp.csr_matrix, opt: PlanOptions) -> tuple[Cover, int]:
    """The locations covering ``mat``'s cells, and how many the greedy cover took."""
    greedy = greedy_cover(mat, opt.coverage_target)
    cover = greedy
    if opt.cover == "exact":
        cover = exact_cover(
            mat, opt.coverage_target, time_limit_s=opt.cover_time_limit_s, hint=greedy
        )
    log.info(
        "cover: %d locations (%s), greedy %d", len(cover.selected), cover.status,
        len(greedy.selected),
    )  # fmt: skip
    return cover, len(greedy.selected)


def _visibility(
    fld: Field,
    scanner: ScannerModel,
    opt: PlanOptions,
    progress: Progress | None,
    chunks: Chunks | None,
    targets: npt.NDArray[np.bool_] | None,
) -> tuple[sp.csr_matrix, sp.csr_matrix, VisibilitySummary]:
    """Which cells each candidate sees: over every cell, over the ``targets`` (every
    cell when None), and the summary counted over the targets."""
    t = time.perf_counter()
    vis = compute_visibility(
        fld, scanner, opt.visibility, samples=opt.samples, step_deg=opt.grid_step_deg,
        progress=progress, chunks=chunks,
    )  # fmt: skip
    elapsed = time.perf_counter() - t
    every = vis.matrix(opt.min_hits)
    mat = every if targets is None else every[:, np.flatnonzero(targets)]
    views = np.asarray(mat.sum(axis=0)).ravel()
    near = vis.cell_min_range()
    return (
        every,
        mat,
        VisibilitySummary(
            mode=vis.mode,
            rays=vis.rays,
            pairs=int(mat.nnz),
            cells_seen_by_none=int((views == 0).sum()),
            median_nearest_range=float(np.median(near[np.isfinite(near)])) if mat.nnz else 0.0,
            time_s=elapsed,
        ),
    )


def _fleet(
    nav: Navigator, pts: F64, ids: list[int | None], via: dict[int, list[Leg]],
    battery: Battery, opt: PlanOptions, tour_s: float,
) -> Fleet:  # fmt: skip
    """The plan's robots' shares, weighed against one robot that starts where they do:
    parked by the locations (``home`` ``near``), or the tour from the Origin
    (``tour_s``)."""
    if opt.home != "near":
        return fleet(nav, pts, ids, via, battery, opt, tour_s)
    lone = fleet(nav, pts, ids, via, battery, msgspec.structs.replace(opt, robots=1), tour_s)
    if opt.robots == 1:  # a fleet of one is its own baseline: split once, not twice
        return msgspec.structs.replace(lone, one_robot_s=lone.makespan_s)
    return fleet(nav, pts, ids, via, battery, opt, lone.makespan_s)


def _tour(
    nav: Navigator, opt: PlanOptions, pts: F64, ids: list[int | None], t0: float
) -> tuple[list[int], TourSummary]:
    """The tour of ``pts`` (the Origin first) as node indices, and its summary: its
    bound when not proven optimal and the nearest-neighbour tour beside it (the paper's
    baseline, the CP-SAT search's first tour); ``t0`` when the stage began."""
    dist = nav.distances(pts)
    tour = solve_tour(dist, opt.tour, opt.tour_time_limit_s)
    # how far from the optimum a tour not proven optimal can be
    bound = None if tour.status == "optimal" else one_tree_bound(dist, tour.length)
    nn = nearest_neighbour(dist)

    def as_ids(order: list[int]) -> list[int]:
        return [0 if k == 0 else int(ids[k] or 0) for k in order] + [0]

    return tour.order, TourSummary(
        nav=opt.nav,
        order=as_ids(tour.order),
        length=tour.length,
        method=tour.method,
        status=tour.status,
        nn_length=nn.length,
        nn_order=as_ids(nn.order),
        time_s=time.perf_counter() - t0,
        bound=bound,
    )


def _candidates(fld: Field, seen: npt.NDArray[np.int64]) -> list[Candidate]:
    """Every candidate location, with the target cells it sees."""
    return [
        Candidate(
            id=int(fld.cand_ids[j]),
            x=float(fld.cand_xy[j, 0]),
            y=float(fld.cand_xy[j, 1]),
            row_lane=int(fld.cand_row_lane[j]),
            cross_lane=int(fld.cand_cross_lane[j]),
            cells_seen=int(seen[j]),
        )
        for j in range(fld.n_candidates)
    ]
