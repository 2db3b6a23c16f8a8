"""The discharge model and the swap rule the planner foretells and the mission follows."""

from __future__ import annotations

import msgspec
import pytest

from common.battery import MARGIN, Battery, Pace, Visit, estimate, must_swap, visit_wh
from common.config import ConfigError
from common.robot import load_robot

HUSKY = Battery()
PACE = Pace(speed=0.5, location_s=360.0)


def test_the_husky_description_states_its_pack() -> None:
    b = load_robot().battery
    assert (b.capacity_wh, b.reserve, b.voltage_v) == (480.0, 0.2, 24.0)
    # the datasheet's 8 h standby and 3 h of typical use (driving)
    assert b.capacity_wh / b.standby_w == 8.0
    assert b.capacity_wh / (b.standby_w + b.drive_w) == 3.0
    assert "480 Wh" in b.describe() and "reserve 20 %" in b.describe()


def test_bad_battery_values_are_refused() -> None:
    for bad in ({"reserve": 1.0}, {"capacity_wh": 0.0}, {"drive_w": -1.0}):
        with pytest.raises(msgspec.ValidationError):
            msgspec.convert(bad, Battery)


def test_a_visit_draws_the_drive_and_the_time_standing() -> None:
    # 100 m at 0.5 m/s: 200 s at 200 W; 360 s at 100 W
    assert visit_wh(HUSKY, PACE, 60.0, 360.0, 40.0) == pytest.approx((200 * 200 + 360 * 100) / 3600)


def test_a_location_waits_for_a_swap_only_when_the_reserve_would_be_touched() -> None:
    need = MARGIN * visit_wh(HUSKY, PACE, 60.0, 360.0, 40.0)
    reserve = HUSKY.reserve_wh
    assert not must_swap(reserve + need + 0.01, HUSKY, PACE, 60.0, 360.0, 40.0)
    assert must_swap(reserve + need - 0.01, HUSKY, PACE, 60.0, 360.0, 40.0)
    # a survey that has drawn more than the model: swaps earlier
    assert must_swap(reserve + need + 0.01, HUSKY, PACE, 60.0, 360.0, 40.0, ratio=1.1)


def test_the_estimate_swaps_where_the_mission_would() -> None:
    # ten locations 20 m apart along a lane from the Origin, each 360 s
    visits = [Visit(20.0, 20.0 * (k + 1), 20.0 * (k + 1)) for k in range(10)]
    big = estimate(visits, 200.0, HUSKY, PACE)
    assert big.swaps == 0 and big.feasible
    assert big.drive_m == pytest.approx(400.0)
    assert big.time_s == pytest.approx(400.0 / 0.5 + 10 * 360.0)
    small = estimate(visits, 200.0, Battery(capacity_wh=100.0, swap_s=600.0), PACE)
    assert small.swaps >= 2 and small.feasible
    # every swap a detour: home from the last location and back out again
    assert small.drive_m > big.drive_m
    assert small.time_s > big.time_s + small.swaps * 600.0
    tiny = estimate(visits, 200.0, Battery(capacity_wh=10.0), PACE)
    assert not tiny.feasible


def test_a_robot_description_with_a_bad_battery_is_one_line(tmp_path: object) -> None:
    from pathlib import Path

    from common.robot import ROBOTS_DIR

    p = Path(str(tmp_path)) / "r.toml"
    p.write_text((ROBOTS_DIR / "husky.toml").read_text().replace("reserve = 0.2", "reserve = 2.0"))
    with pytest.raises(ConfigError, match="reserve"):
        load_robot(p)
