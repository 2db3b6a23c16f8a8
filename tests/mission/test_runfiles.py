"""The effective manifest a mission folder keeps: the deployment's manifest with the
field and robot as resolved, loadable as a manifest again."""

from __future__ import annotations

from pathlib import Path

from common.config import load_manifest
from common.robot import robot_path
from services.mission.runfiles import effective_manifest


def test_the_effective_manifest_loads_again_with_the_resolved_field(tmp_path: Path) -> None:
    src = tmp_path / "m.toml"
    src.write_text(
        'machine = "robot"\nclock = "wall"\nfield = "engr"\nrun_dir = "runs"\n'
        '[zenoh]\nlisten = ["tcp/127.0.0.1:7447"]\n'
        "[services.mission]\nsettle_s = 2.5\n"
    )
    out = tmp_path / "manifest.toml"
    out.write_bytes(effective_manifest(src, "/data/fields/trial-7.geojson"))
    m = load_manifest(out)
    assert m.field == "/data/fields/trial-7.geojson"
    assert m.robot == str(robot_path(""))
    assert m.services["mission"] == {"settle_s": 2.5}
    assert m.machine == "robot" and m.zenoh.listen == ["tcp/127.0.0.1:7447"]
    assert out.read_text().startswith(f"# the manifest this mission ran with: {src}")
