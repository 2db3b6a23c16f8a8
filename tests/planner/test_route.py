"""BR/AHA/lane distances, tours and legs on hand-worked cases and the paper's route."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from common.field import load_field
from common.messages.nav import legs_length
from services.planner.route import Navigator, aha_distance, br_distance
from services.planner.tsp import (
    circuit_cpsat,
    guided_local_search,
    nearest_neighbour,
    one_tree_bound,
    solve_tour,
    tour_length,
)
from services.planner.waypoints import heading, tour_legs

PAPER_ENGR_ROUTE = [14, 26, 4, 17, 30, 65, 43, 74, 60, 39, 55]


def test_br_is_manhattan():
    a, b = np.array([[0.0, 0.0]]), np.array([[3.0, -4.0]])
    assert br_distance(a, b)[0, 0] == 7.0


def test_aha_goes_round_by_the_nearer_edge():
    a, b = np.array([[0.0, 2.0]]), np.array([[4.0, 3.0], [0.0, 9.0], [4.0, 8.0]])
    d = aha_distance(a, b, 0.0, 10.0)[0]
    assert d[0] == 2 + 4 + 3  # via y = 0
    assert d[1] == 7  # same cross lane: straight
    assert d[2] == min(2 + 4 + 8, 8 + 4 + 2)  # 14 either way


@pytest.fixture(scope="module")
def engr():
    return load_field("engr")[1]


def _points(field, ids):
    return np.vstack([field.origin_xy] + [field.cand_xy[field.candidate_index(i)] for i in ids])


def test_paper_route_lengths(engr):
    # PAPER_NOTES: at 1.8 m x 4.5 m lane pitch (our ENGR) the paper's nodes give AHA
    # 144.0 m (and its order is the AHA optimum), BR optimum 104.4 m, NN (AHA) 183.6 m
    pts = _points(engr, PAPER_ENGR_ROUTE)
    d_aha = Navigator(engr, "aha").distances(pts)
    assert tour_length(d_aha, list(range(12))) == pytest.approx(144.0)
    assert circuit_cpsat(d_aha).length == pytest.approx(144.0)
    assert circuit_cpsat(Navigator(engr, "br").distances(pts)).length == pytest.approx(104.4)
    assert nearest_neighbour(d_aha).length == pytest.approx(183.6)


def test_lanes_default_equals_aha_and_blocking_lengthens(engr):
    pts = engr.cand_xy[::5]
    aha = Navigator(engr, "aha").distances(pts)
    assert np.allclose(Navigator(engr, "lanes").distances(pts), aha)
    all_open = Navigator(engr, "lanes", open_rows=list(range(11))).distances(pts)
    assert np.allclose(all_open, Navigator(engr, "br").distances(pts))
    blocked = Navigator(engr, "lanes", open_cross=[0, 1, 2, 4, 5, 6]).distances(pts[:3])
    assert (blocked >= aha[:3, :3] - 1e-9).all()
    with pytest.raises(ValueError, match="open_rows: lane index 11"):
        Navigator(engr, "lanes", open_rows=[11])


def test_cpsat_is_optimal_on_random_instances():
    rng = np.random.default_rng(3)
    for n in (4, 6, 8):
        xy = rng.uniform(0, 50, (n, 2))
        d = br_distance(xy, xy)
        best = min(tour_length(d, [0, *p]) for p in itertools.permutations(range(1, n)))
        cp = circuit_cpsat(d, 10)
        assert cp.status == "optimal" and cp.length == pytest.approx(best, abs=1e-2)
        assert cp.order[0] == 0


def test_the_one_tree_bound_is_below_every_tour_and_tight_on_small_ones():
    rng = np.random.default_rng(4)
    for n in (5, 9, 13):
        xy = rng.uniform(0, 50, (n, 2))
        d = br_distance(xy, xy)
        exact = circuit_cpsat(d, 60)
        assert exact.status == "optimal"  # the reference is the proven shortest tour
        best = exact.length
        bound = one_tree_bound(d, 1.1 * best)
        assert bound <= best + 1e-6 and bound >= 0.97 * best
    xy = rng.uniform(0, 200, (120, 2))
    d = br_distance(xy, xy)
    gls = guided_local_search(d, 1.0)
    assert 0.9 * gls.length < one_tree_bound(d, gls.length) <= gls.length
    # asymmetric: bounded by the cheaper direction of each pair
    skew = d + np.triu(np.full_like(d, 5.0), 1)
    assert one_tree_bound(skew, 2 * gls.length) <= one_tree_bound(d, gls.length) + 1e-6


def test_large_tours_beat_nearest_neighbour():
    rng = np.random.default_rng(5)
    xy = rng.uniform(0, 200, (120, 2))
    d = br_distance(xy, xy)
    gls = guided_local_search(d, 2.0)
    assert sorted(gls.order) == list(range(120)) and gls.order[0] == 0
    assert gls.length <= nearest_neighbour(d).length
    assert solve_tour(d, "auto", 1.0).method == "guided-local-search"
    with pytest.raises(ValueError, match="tour method 'fast'"):
        solve_tour(d[:20, :20], "fast")


@pytest.mark.parametrize("nav", ["br", "aha", "lanes"])
def test_legs_follow_lanes_and_add_up(engr, nav):
    nv = Navigator(engr, nav)
    pts = _points(engr, PAPER_ENGR_ROUTE)
    d = nv.distances(pts)
    tour = circuit_cpsat(d)
    ids = [None, *PAPER_ENGR_ROUTE]
    legs = tour_legs(nv, pts, tour.order, ids)
    assert legs_length(legs) == pytest.approx(tour.length)
    lanes_x, lanes_y = set(engr.cross_lanes_x.round(6)), set(engr.row_lanes_y.round(6))
    for a, b in itertools.pairwise(legs):
        assert (a.x1, a.y1) == (b.x0, b.y0)  # contiguous
        if a.scan_id is None:
            assert a.final_yaw == pytest.approx(heading(b))  # rotate to face the next leg
        else:
            assert a.final_yaw is None  # scan as it arrived: no turn shifts the scanner
    for g in legs:
        assert g.x0 == g.x1 or g.y0 == g.y1  # axis-aligned
        if g.x0 == g.x1:
            assert round(g.x0, 6) in lanes_x
        else:
            assert round(g.y0, 6) in lanes_y
            if nav != "br":
                assert round(g.y0, 6) in {
                    round(engr.row_lanes_y[0], 6),
                    round(engr.row_lanes_y[-1], 6),
                }
    scans = [g.scan_id for g in legs if g.scan_id is not None]
    assert scans == [ids[k] for k in tour.order[1:]]
    assert (legs[0].x0, legs[0].y0) == tuple(engr.origin_xy)
    assert (legs[-1].x1, legs[-1].y1) == tuple(engr.origin_xy)
    assert legs[-1].final_yaw is None


def test_scan_at_the_start_corner_gets_a_zero_length_leg(engr):
    nv = Navigator(engr, "aha")
    origin_id = int(engr.cand_ids[engr.cand_xy.tolist().index(engr.origin_xy.tolist())])
    pts = _points(engr, [origin_id, 14])
    legs = tour_legs(nv, pts, [0, 1, 2], [None, origin_id, 14])
    assert legs[0].scan_id == origin_id and (legs[0].x0, legs[0].y0) == (legs[0].x1, legs[0].y1)
    assert not math.isnan(legs_length(legs))
