"""The served web viewer in a real browser: headless Chromium opens it during a short
simulated survey, and the screenshot shows the field, not a blank page.

Set ``PHENOROVER_SCREENSHOT=path.png`` to keep the screenshot (docs/dashboard.png
comes from here)."""

from __future__ import annotations

import os
import time
from pathlib import Path
from urllib.parse import quote

import numpy as np
import pytest
from PIL import Image

from common.client import wait_alive
from common.messages.mission import MissionPhase
from tests.conftest import Procs, free_port
from tests.e2e.cdp import Browser, find_chromium
from tests.integration.test_mission import SERVICES, Deployment


def scene_share(png: Path) -> tuple[float, float]:
    """(share of pixels in the scene's greens, yellows and reds, grey-level spread).
    The viewer's own chrome is grey and blue; the field's plots and cells are not."""
    a = np.asarray(Image.open(png).convert("RGB")).astype(np.int32)
    r, g, b = a[..., 0], a[..., 1], a[..., 2]
    coloured = (np.maximum(r, g) - b > 60) & (np.abs(r - g) < 200)
    return float(coloured.mean()), float(a.std())


def test_served_viewer_shows_the_scene_in_chromium(procs: Procs, tmp_path: Path) -> None:
    exe = find_chromium()
    if exe is None:  # make e2e asks for this test: a run without a browser is a failure
        pytest.fail("no chromium here (Debian: apt-get install chromium)")
    grpc, web = free_port(), free_port()
    viz = (
        f'[services.viz]\nserve = true\nbind = "127.0.0.1"\ngrpc_port = {grpc}\nweb_port = {web}\n'
    )
    d = Deployment(procs, tmp_path, viz)
    browser = None
    try:
        assert wait_alive(d.session, {*SERVICES, "viz"}, timeout=60)
        s = d.start()
        d.wait(lambda x: x.mission == s.mission and x.phase == MissionPhase.DRIVING)
        proxy = f"rerun+http://127.0.0.1:{grpc}/proxy"
        browser = Browser(exe)
        browser.open(f"http://127.0.0.1:{web}/?url={quote(proxy, safe='')}")
        shot = Path(os.environ.get("PHENOROVER_SCREENSHOT", tmp_path / "viewer.png"))
        share, spread = 0.0, 0.0
        deadline = time.monotonic() + 120  # wasm download, compile and first frames
        while time.monotonic() < deadline:
            time.sleep(3.0)
            browser.screenshot(shot)
            share, spread = scene_share(shot)
            if share > 0.01:
                break
        assert spread > 10, f"blank page (pixel spread {spread:.1f}); see {shot}"
        assert share > 0.01, f"viewer up but no field drawn ({share:.2%} scene pixels); {shot}"
    finally:
        if browser is not None:
            browser.close()
        d.close()
