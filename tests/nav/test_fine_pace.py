"""What a location's end costs: a long creep slows as it nears the goal instead of
crawling all the way, and a route that ends nowhere a scan is taken (the way home)
skips the fine phase."""

from __future__ import annotations

import math

from common.messages.nav import Leg
from services.nav.follower import Follower, FollowerConfig
from tests.nav.test_follower import run_lagging


def creep_back(cfg: FollowerConfig, past: float) -> tuple[float, float, str]:
    """A robot stopped ``past`` metres beyond its goal creeps back: (seconds to
    arrive, how far from the goal it ends, the arrival's detail)."""
    f = Follower(cfg)
    f.start("over", [Leg(x0=0, y0=0, x1=2, y1=0)])
    at: list[float] = []
    x, y, _, events = run_lagging(f, 2.0 + past, 0.0, 0.0, at=at)
    assert events == ["arrived"], events
    return at[0], math.hypot(x - 2.0, y), f.end_detail


def test_a_long_creep_takes_seconds_and_ends_as_slowly() -> None:
    cfg = FollowerConfig()
    took, off, detail = creep_back(cfg, 0.30)
    assert "creep -300 mm" in detail, detail
    assert off <= cfg.fine_tolerance_m
    # the same creep at the slowest speed all the way
    crawl, crawl_off, _ = creep_back(FollowerConfig(creep_max_speed=cfg.creep_speed), 0.30)
    assert took < crawl - 0.3 / cfg.creep_speed / 2, (took, crawl)
    # it ends as slowly, so it lands as close (within a few millimetres)
    assert abs(off - crawl_off) < 0.005, (off, crawl_off)


def test_a_short_creep_is_unchanged() -> None:
    cfg = FollowerConfig()
    took, off, _ = creep_back(cfg, 0.03)
    crawl, crawl_off, _ = creep_back(FollowerConfig(creep_max_speed=cfg.creep_speed), 0.03)
    assert (took, off) == (crawl, crawl_off)


def test_a_route_not_to_a_scan_ends_where_its_leg_does() -> None:
    """The way home, 4 cm beside its line and 3 deg off: no settle, creep or
    re-approach, and arrived within the route's own tolerance at any heading."""
    legs = [Leg(x0=0, y0=0, x1=3, y1=0)]
    home = Follower(FollowerConfig())
    home.start("home", legs, arrival_tolerance_m=2.0, to_scan=False)
    at: list[float] = []
    *_, events = run_lagging(home, 0.0, 0.04, math.radians(3.0), at=at)
    assert events == ["arrived"] and home.fine.history == []
    assert "settle" not in home.end_detail, home.end_detail
    scan = Follower(FollowerConfig())
    scan.start("scan", legs)
    at_scan: list[float] = []
    *_, events = run_lagging(scan, 0.0, 0.04, math.radians(3.0), at=at_scan)
    assert events == ["arrived"] and "settle" in scan.end_detail
    assert at[0] < at_scan[0] - FollowerConfig().fine_settle_s
