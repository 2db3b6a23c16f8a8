"""``phenorover eval register``: registration outputs scored against the simulator's
truth, on a synthetic case whose errors are known exactly: navigation off by 3 cm
along x, C2C by 1 cm up, the target-based poses exact."""

from __future__ import annotations

import json
from pathlib import Path

import msgspec
import numpy as np
import pytest

from common.geo import se3
from common.pointcloud import PosedScan, write_e57
from common.poses import F64, apply, inv
from phenorover.eval.register.cli import main
from phenorover.eval.register.paper import TABLE1, compare
from services.register.outcome import ScanReport
from services.sim.truth_file import ScanTruth, write_truth

TARGETS = np.array([[2.0, 1.0, 1.2], [4.0, -1.0, 1.1], [6.0, 0.5, 1.3]])
NAV_ERR = np.array([0.03, 0.0, 0.0])
C2C_ERR = np.array([0.0, 0.0, 0.01])


def _shifted(m: F64, d: np.ndarray) -> F64:
    out = m.copy()
    out[:3, 3] += d
    return out


def _rows(m: F64) -> list[list[float]]:
    return [[float(v) for v in r] for r in m]


def _outputs(tmp: Path, truth: bool = True, n: int = 3) -> Path:
    """A registration's outputs for ``n`` scans at known poses, each seeing every
    target, with truth files beside the (absent) scan files when ``truth``."""
    out = tmp / "run"
    out.mkdir()
    rng = np.random.default_rng(3)
    scans, rows = [], []
    for k in range(n):
        pose = se3(0.01 * k, -0.02 * k, 0.3 * k, [1.5 * k, 0.2 * k, 1.0])
        pts = rng.uniform(-5, 5, size=(300, 3))
        centres = apply(inv(pose), TARGETS)
        name, file = f"scan_{k + 1:03d}", tmp / "card" / f"Scan_{k + 1:05d}.e57"
        scans.append(PosedScan(pts, np.ones(len(pts), np.float32), pose, name))
        rows.append(
            ScanReport(
                name=name,
                points=len(pts),
                downsampled=len(pts),
                spheres=len(centres),
                sphere_rms=[0.001] * len(centres),
                targets=len(centres),
                target_solved=True,
                nav_pose=_rows(_shifted(pose, NAV_ERR)),
                c2c_pose=_rows(_shifted(pose, C2C_ERR)),
                target_pose=_rows(pose),
                file=str(file),
                sphere_centres=[tuple(c) for c in centres.tolist()],
                sphere_targets=[0, 1, 2],
            )
        )
        if truth:
            file.parent.mkdir(exist_ok=True)
            write_truth(
                file,
                ScanTruth(
                    stamp_ns=k, scanner_pose=_rows(pose), x=0, y=0, z=0, roll=0, pitch=0, yaw=0
                ),
            )
    write_e57(out / "registered.e57", scans)
    report = {
        "navigation": {"mission": "synthetic-1"},
        "registration": {"vs_reference": []},
        "registration_detail": {"scans": msgspec.to_builtins(rows)},
        "outputs": {"e57": "registered.e57"},
    }
    (out / "report.json").write_text(json.dumps(report))
    return out


def test_known_errors_are_measured(tmp_path: Path) -> None:
    run = _outputs(tmp_path)
    assert main([str(run)]) == 0
    got = json.loads((run / "eval_register.json").read_text())
    truth = got["truth"]
    assert truth["scans"] == 3 and truth["targets"] == 3
    m = truth["methods"]
    assert set(m) == {"navigation", "c2c", "target_based"}
    nav, c2c, tgt = m["navigation"], m["c2c"], m["target_based"]
    assert nav["points"]["mean"] == pytest.approx(0.03, abs=1e-9)
    assert nav["points"]["max"] == pytest.approx(0.03, abs=1e-9)
    assert nav["points"]["per_scan_mean"] == pytest.approx([0.03] * 3, abs=1e-9)
    assert nav["targets"]["count"] == 9
    assert nav["targets"]["horizontal"] == pytest.approx(0.03, abs=1e-9)
    assert nav["targets"]["vertical"] == pytest.approx(0.0, abs=1e-9)
    assert c2c["points"]["mean"] == pytest.approx(0.01, abs=1e-9)
    assert c2c["targets"]["vertical"] == pytest.approx(0.01, abs=1e-9)
    assert c2c["targets"]["horizontal"] == pytest.approx(0.0, abs=1e-9)
    assert tgt["points"]["max"] == pytest.approx(0.0, abs=1e-9)
    assert tgt["targets"]["max"] == pytest.approx(0.0, abs=1e-9)
    md = (run / "eval_register.md").read_text()
    assert "| Nav. sensors only | 3.00 | 3.00 | 0.00 | 3.00 | 3.00 | 3.00 |" in md


def test_a_real_survey_has_no_truth_and_gets_the_paper_comparison(tmp_path: Path) -> None:
    run = _outputs(tmp_path, truth=False)
    assert main([str(run)]) == 0
    got = json.loads((run / "eval_register.json").read_text())
    assert got["truth"] is None and got["paper"] == {
        "table1": [],
        "hausdorff": {"ours": None, "paper": got["paper"]["hausdorff"]["paper"]},
    }


def test_truth_for_some_scans_only_is_one_line(tmp_path: Path, capsys) -> None:
    run = _outputs(tmp_path)
    (tmp_path / "card" / "Scan_00002.truth.json").unlink()
    assert main([str(run)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "scan_002" in err[0]
    assert not (run / "eval_register.json").exists()


def test_no_report_is_one_line(tmp_path: Path, capsys) -> None:
    assert main([str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "report.json" in err[0] and "phenorover register" in err[0]


def test_paper_table1_beside_ours() -> None:
    row = {
        "method": "c2c",
        "targets": {"mean_cm": 1.0, "horizontal_cm": 0.8, "vertical_cm": 0.5},
        "points": {"max_cm": 9.0, "mean_cm": 4.0},
        "overlap": {"max_cm": 2.5, "mean_cm": 1.5, "pairs": 3, "radius_cm": 30.0},
        "hausdorff": {"mean_cm": 1.1, "sd_cm": 0.7, "below_2cm": 0.9, "below_3cm": 0.97},
    }
    got = compare({"vs_reference": [row]})
    assert got is not None
    [c2c] = got["table1"]
    # the paper's scan point statistics are SCENE's overlap residuals: set beside ours,
    # not beside the distances to the target-based reference
    assert c2c["ours"]["mean_point_cm"] == 1.5 and c2c["paper"]["mean_point_cm"] == 2.07
    assert c2c["ours"]["max_point_cm"] == 2.5
    assert c2c["paper"] == TABLE1["c2c"]
    assert (
        got["hausdorff"]["ours"]["mean_cm"] == 1.1 and got["hausdorff"]["paper"]["mean_cm"] == 1.25
    )
