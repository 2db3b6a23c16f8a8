"""Planner options and results: msgspec Structs, so they decode from TOML, travel over
the bus and are written as plan.json unchanged. Distances in metres, angles in radians,
times in seconds, coordinates in the ``field`` frame. Candidate ids follow
:mod:`common.field`; id 0 stands for the start corner (the paper's "Origin")."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

import msgspec
import numpy as np
import numpy.typing as npt

from common.battery import Battery, Estimate, Pace
from common.field import FieldLayout, ScannerModel
from common.files import read_regular
from common.messages.core import Array, Coordinate, Finite, Message, NonNegative, Positive
from common.messages.nav import Leg, legs_length

Seconds = Positive


class PlanOptions(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """How to plan.

    ``nav``: ``br`` | ``aha`` | ``lanes`` (see :mod:`services.planner.route`; with
    ``lanes``, ``open_rows``/``open_cross`` list the passable lane indices).
    ``cover``: ``greedy`` (the paper's Algorithm 1) or ``exact`` (CP-SAT minimum).
    ``visibility``: ``exact`` (``samples`` x ``samples`` points per exposed cell face)
    or ``grid`` (the scanner's angular grid, ``grid_step_deg`` overriding its step).
    ``coverage_target``: fraction of the coverable cells to cover; ``min_hits``: rays
    (or sample points) a candidate needs on a cell to count as seeing it.
    ``tour``: ``auto`` | ``cp-sat`` | ``gls``. ``pace``: how fast the
    survey goes, for its time estimate and the swaps it foretells
    (:class:`common.battery.Pace`). ``robots``: how many robots share the survey
    (the locations split between them, :mod:`services.planner.fleet`). ``home``:
    where the robots start and end: ``origin``, one robot at the field's Origin (the
    paper's survey), several parked along the edge lanes from the Origin's corner;
    ``near``, parked beside the edge lanes by the cross lane nearest the chosen
    locations (:func:`common.lanes.homes`), each robot's share a part of the plan,
    one robot's too. The plan says where each robot parks.
    """

    nav: Literal["br", "aha", "lanes"] = "aha"
    cover: Literal["greedy", "exact"] = "exact"
    visibility: Literal["exact", "grid"] = "exact"
    samples: Annotated[int, msgspec.Meta(ge=1, le=16)] = 3
    grid_step_deg: Annotated[float, msgspec.Meta(gt=0, le=45)] | None = None
    coverage_target: Annotated[float, msgspec.Meta(gt=0, le=1)] = 1.0
    min_hits: Annotated[int, msgspec.Meta(ge=1)] = 1
    cover_time_limit_s: Seconds = 30.0
    tour: Literal["auto", "cp-sat", "gls"] = "auto"
    tour_time_limit_s: Seconds = 10.0
    open_rows: list[int] | None = None
    open_cross: list[int] | None = None
    pace: Pace = msgspec.field(default_factory=Pace)
    robots: Annotated[int, msgspec.Meta(ge=1, le=8)] = 1
    home: Literal["origin", "near"] = "origin"


class Candidate(msgspec.Struct, frozen=True, kw_only=True):
    """A candidate scan location: lane intersection (row-gap lane, cross lane)."""

    id: int
    x: Coordinate
    y: Coordinate
    row_lane: int
    cross_lane: int
    cells_seen: int


class CoverSummary(msgspec.Struct, frozen=True, kw_only=True):
    """``status``: greedy | optimal | feasible | greedy-fallback; ``gap`` is
    (count - lower bound) / count for CP-SAT (0 when optimal), None for greedy."""

    method: str
    count: int
    greedy_count: int
    cells_total: int
    cells_coverable: int
    cells_target: int
    cells_covered: int
    status: str
    bound: Finite | None
    gap: Finite | None
    time_s: NonNegative


class TourSummary(msgspec.Struct, frozen=True, kw_only=True):
    """The closed tour ``order`` (ids, starting and ending at 0) under ``nav``;
    ``nn_length`` is the nearest-neighbour baseline under the same distances.
    ``bound``: a lower bound on the shortest tour when the tour is not proven optimal
    (Held-Karp's 1-tree bound), so ``length / bound - 1`` bounds how far from the
    optimum it is."""

    nav: str
    order: list[int]
    length: NonNegative
    method: str
    status: str
    nn_length: NonNegative
    nn_order: list[int]
    time_s: NonNegative
    bound: NonNegative | None = None


class VisibilitySummary(msgspec.Struct, frozen=True, kw_only=True):
    mode: str
    rays: int
    pairs: int
    cells_seen_by_none: int
    median_nearest_range: NonNegative
    time_s: NonNegative


class FleetPart(msgspec.Struct, frozen=True, kw_only=True):
    """One robot's share of a survey: ``order`` its tour (candidate ids, 0 its home
    first and last), ``legs`` the legs of it, from and back to ``home`` (where the
    robot parks, off the lanes: :mod:`services.planner.fleet`), ``survey`` its time
    with its swaps."""

    robot: Annotated[int, msgspec.Meta(ge=1)]
    order: list[int]
    legs: list[Leg]
    survey: Estimate
    home: tuple[Coordinate, Coordinate]


class Fleet(msgspec.Struct, frozen=True, kw_only=True):
    """The locations split between robots so that the slowest finishes first:
    ``parts`` one per robot; ``one_robot_s``: the survey's time with one robot at the
    same pace and battery, parked as these are (the plan's own tour from the Origin,
    or with ``home`` ``near`` one robot's parked by the locations), to compare;
    ``status`` of the split (``heuristic``: guided local search to its time limit);
    ``time_s`` it took."""

    parts: list[FleetPart]
    one_robot_s: NonNegative
    status: str
    time_s: NonNegative

    @property
    def makespan_s(self) -> float:
        return max(p.survey.time_s for p in self.parts)


class PlanResult(Message, frozen=True, kw_only=True):
    """Everything a survey needs, plus what it took to get it. ``plot_boxes`` is the
    (P, 6) float64 array of plot boxes; ``origin`` the tour start (x, y);
    ``cell_views`` the (C,) int64 count, per cell of the field, of the selected
    locations that see it (what the dashboard colours the cells by).
    ``footprints``: the plots' boxes in the field file, when ``plot_boxes`` are not
    them (a plan on the crop as a survey measured it plans on the measured canopy;
    its traits are still cut by the field book's plots); :meth:`plot_footprints`.
    ``via_origin``: each selected location's round trip from the Origin along the
    lanes (the way a robot leaves for a battery swap and comes back); ``survey``: the
    survey's time and energy at the options' pace, with the swaps the request's
    battery asks for (:func:`common.battery.estimate`); ``fleet``: with several
    robots, each one's share; ``share``: the robot (1..N) whose share of such a plan
    this is (:meth:`share_of`), its locations, legs, tour and time only."""

    field: str
    layout: FieldLayout
    scanner: ScannerModel
    options: PlanOptions
    origin: tuple[Coordinate, Coordinate]
    plot_boxes: Array
    candidates: list[Candidate]
    selected: list[int]
    visibility: VisibilitySummary
    cover: CoverSummary
    tour: TourSummary
    legs: list[Leg]
    timings: dict[str, NonNegative]
    cell_views: Array | None = None
    footprints: Array | None = None
    via_origin: dict[int, list[Leg]] | None = None
    survey: Estimate | None = None
    fleet: Fleet | None = None
    share: Annotated[int, msgspec.Meta(ge=1)] | None = None

    def share_of(self, robot: int) -> PlanResult:
        """Robot ``robot``'s share (1..N) of a plan split between N robots: its
        locations, legs, tour and time; the field, candidates, cells and the split
        itself as they are. ValueError, one line, when the plan has no such share."""
        if self.fleet is None or self.share is not None:
            raise ValueError(
                "the plan is not split between robots (phenorover plan --robots N makes one)"
            )
        parts = {p.robot: p for p in self.fleet.parts}
        if robot not in parts:
            raise ValueError(f"the plan is split between {len(parts)} robots: no share {robot}")
        part = parts[robot]
        length = legs_length(part.legs)
        tour = msgspec.structs.replace(
            self.tour,
            order=part.order,
            length=length,
            method=f"robot {robot} of {len(parts)} ({self.tour.method}, split {self.fleet.status})",
            nn_length=length,  # the whole tour's baselines and bound are not this share's
            nn_order=part.order,
            bound=None,
        )
        return msgspec.structs.replace(
            self,
            selected=[c for c in part.order if c != 0],
            legs=part.legs,
            tour=tour,
            survey=part.survey,
            share=robot,
        )

    def legs_scan_ids(self) -> list[int]:
        """The scan ids in tour order (the legs that end at a location)."""
        return [g.scan_id for g in self.legs if g.scan_id is not None]

    def plot_footprints(self) -> npt.NDArray[np.float64]:
        """(P, 6) the plots as the field file has them (whatever boxes were planned on)."""
        a = self.plot_boxes if self.footprints is None else self.footprints
        return np.asarray(a.numpy(), dtype=np.float64).reshape(-1, 6)


class PlanRequest(Message, frozen=True, kw_only=True):
    """Ask the planner for a plan. Give the field exactly one way: ``layout`` (layout
    parameters), ``geojson`` (the text of a FeatureCollection of plot polygons) or
    ``name`` (an example or a field file on the planner's host). ``scanner`` and
    ``battery`` are the surveying robot's (its robot description)."""

    layout: FieldLayout | None = None
    geojson: str = ""
    name: str = ""
    scanner: ScannerModel = msgspec.field(default_factory=ScannerModel)
    options: PlanOptions = msgspec.field(default_factory=PlanOptions)
    battery: Battery = msgspec.field(default_factory=Battery)


# a 100 x 100-plot field's plan is tens of megabytes; a file far beyond is not one
MAX_PLAN_BYTES = 1 << 30


def read_plan(path: Path, what: str) -> PlanResult:
    """The plan in the JSON file ``path`` (``phenorover plan``'s ``plan.json``);
    ValueError, one line beginning with ``what`` (how the caller names the file):
    unreadable, not a regular file (a FIFO would never end), larger than any plan, or
    not a plan."""
    try:
        data = read_regular(path, MAX_PLAN_BYTES, "a plan")
    except OSError as exc:
        raise ValueError(f"{what}: {exc.strerror}") from None
    except ValueError as exc:
        raise ValueError(f"{what}: {exc}") from None
    try:
        return msgspec.json.decode(data, type=PlanResult)
    except msgspec.DecodeError as exc:
        raise ValueError(f"{what}: not a plan ({exc})") from None
