"""Fixtures of the base's ROS 2 tests."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
import zenoh

from common.config import zenoh_config


@pytest.fixture
def two_sessions(router_endpoint: str) -> Iterator[tuple[zenoh.Session, zenoh.Session]]:
    """Two peers on the test router, as two ROS 2 processes on one machine."""
    a = zenoh.open(zenoh_config("peer", ["tcp/127.0.0.1:0"], [router_endpoint]))
    b = zenoh.open(zenoh_config("peer", ["tcp/127.0.0.1:0"], [router_endpoint]))
    yield a, b
    b.close()
    a.close()
