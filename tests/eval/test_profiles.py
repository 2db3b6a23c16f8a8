"""The navigation profiles are configurations our services accept."""

from __future__ import annotations

import tomllib

import msgspec
import pytest

from phenorover.eval import profiles
from services.mission.config import MissionConfig
from services.nav.config import NavConfig
from services.register.config import RegisterRunConfig
from tests.conftest import REPO


def test_the_paper_profile_is_a_valid_nav_config_over_the_shipped_manifest() -> None:
    with (REPO / "deploy" / "sim.toml").open("rb") as f:
        shipped = tomllib.load(f)
    m = profiles.apply(shipped, "paper")
    nav = msgspec.convert(m["services"]["nav"], NavConfig)
    assert not nav.tilt.enabled and not nav.follower.fine and not nav.ekf.gate
    assert not nav.ekf.lag_compensation and not nav.ekf.zero_velocity_updates
    assert not nav.gyro.enabled and nav.follower.max_speed == 0.5
    # it scans where it stops, as the paper's robot did
    mission = msgspec.convert(m["services"]["mission"], MissionConfig)
    assert mission.arrival_tolerance_m == 0.25  # each route to a location carries it
    assert nav.follower.arrival_heading_tolerance_deg == 180.0
    assert nav.follower.heading_tolerance_deg == 2.0  # its corner turns keep the paper's
    # its registration is the clouds' alone: the paper's C2C left the spheres out
    reg = msgspec.convert(m["services"]["register"], RegisterRunConfig)
    assert not reg.register.refine.use_targets
    assert reg.register.refine.coarse_correspondence == 0.3
    assert reg.register.refine.nav_sigma_xy == 0.02
    # the manifest's own settings stay where the profile says nothing
    assert m["services"]["sim"] == shipped["services"]["sim"]
    assert profiles.apply(shipped, "ours") == shipped
    with pytest.raises(KeyError, match="no navigation profile 'fast'"):
        profiles.apply(shipped, "fast")
