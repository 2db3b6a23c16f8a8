"""The base obeys one commander (nav): once its last commander is gone, a command
still in flight from it (delivered on another thread than its token's end) is void,
until a commander is back. The service runs in-process on a real bus; its callbacks
are called in the order the race would deliver them."""

from __future__ import annotations

import logging
from pathlib import Path

from common.clock import WallClock
from common.messages.base import Twist
from common.service import Context
from common.transport import Bus
from services.base.config import BaseConfig
from services.base.service import BaseService

NAV = "phenorover/alive/robot/nav/{pid}/1"


def test_a_gone_commanders_late_command_does_not_move_the_wheels(
    client_bus: Bus, tmp_path: Path
) -> None:
    ctx = Context("base", "test", client_bus, WallClock(), logging.getLogger("t"), tmp_path)
    base = BaseService(ctx, BaseConfig(backend="sim"))
    now = ctx.clock.now_ns
    base._on_alive(NAV.format(pid=1), True)
    base._on_cmd(Twist(linear_x=0.5))
    assert base.gate.output(now()) == (0.5, 0.0)
    base._on_alive(NAV.format(pid=1), False)
    assert base.gate.output(now()) == (0.0, 0.0)
    base._on_cmd(Twist(linear_x=0.5))  # its last command, delivered after its end
    assert base.gate.output(now()) == (0.0, 0.0), "a dead commander moved the wheels"
    base._on_alive(NAV.format(pid=2), True)  # nav restarted
    base._on_cmd(Twist(linear_x=0.3))
    assert base.gate.output(now()) == (0.3, 0.0)
