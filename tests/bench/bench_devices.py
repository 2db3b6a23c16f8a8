"""Devices benchmark: the simulated GNSS compass over 10 minutes of driving, through
the whole receiver path (RTK error model -> NMEA GST/GGA -> parser -> fixes ->
compass), and the time per simulated FARO scan of ENGR at 0.36 deg.

Prints the error models beside the results and writes them through
phenorover.eval.results. Report, never assert; a part that fails makes it exit 1.
    python tests/bench/bench_devices.py [--json OUT] [--minutes 10]
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from common.field import load_field
from common.field_geojson import field_frame
from common.geo import wrap_angle
from common.pointcloud import PosedScan, read_e57, write_e57
from common.robot import default_robot
from phenorover.eval.error_models import compass, faro, rtk
from phenorover.eval.results import Bench
from services.gnss.compass import Compass
from services.gnss.nmea import Gga, Gst, parse_sentence
from services.gnss.receiver import receiver_output
from services.gnss.rtk_model import RtkErrorModel, RtkModelConfig
from services.gnss.solution import FixBuilder, heading
from services.planner.core import plan
from services.sim.render import ScanSettings
from services.sim.robot import RobotState
from services.sim.scene import LABEL_NAMES
from services.sim.world import World
from services.sim.world_config import WorldConfig


def _read(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points, intensity and pose of a single-scan E57 file."""
    (scan,) = read_e57(path)
    return scan.points, scan.intensity, scan.pose


def compass_drive(minutes: float, seed: int = 7) -> dict[str, float]:
    layout, fld = load_field("engr")
    world = World(layout, fld)
    frame = field_frame(layout)
    rtk = RtkModelConfig()
    rng = np.random.default_rng(seed)
    models = {a: RtkErrorModel(rtk, np.random.default_rng([seed, a])) for a in (1, 2)}
    builders = {a: FixBuilder(a, {"FIX": 0.014, "FLOAT": 0.25, "SINGLE": 1.2}) for a in (1, 2)}
    cfg = Compass.of(default_robot())
    s = world.settle(RobotState(x=28.5, y=1.0, yaw=math.pi))
    dt, n = 0.02, int(minutes * 60 / 0.02)
    errs, valid, total = [], 0, 0
    for k in range(n):
        t = k * dt
        # a lap around the field's outer lanes, turning in place at the corners
        phase = (t % 80.0) / 80.0
        v, w = (0.5, 0.0) if phase < 0.85 else (0.0, 0.4)
        s = world.step_robot(s, v, w, dt, rng)
        if k % 5:
            continue
        truth = world.gnss_truth(s)
        fixes = {}
        for a in (1, 2):
            p = (float(truth[a - 1, 0]), float(truth[a - 1, 1]), float(truth[a - 1, 2]))
            text = receiver_output(frame, p, models[a].step(0.1), t)
            for line in text.encode().splitlines():
                sent = parse_sentence(line)
                if isinstance(sent, Gst):
                    builders[a].on_gst(sent)
                elif isinstance(sent, Gga):
                    fix = builders[a].on_gga(sent, int(t * 1e9))
                    if fix is not None:
                        fixes[a] = fix
        if len(fixes) < 2:
            continue
        total += 1
        hd = heading(fixes[1], fixes[2], frame, cfg)
        if hd.valid:
            valid += 1
            errs.append(math.degrees(wrap_angle(hd.yaw - s.yaw)))
    e = np.array(errs)
    noise = rtk.fix
    return {
        "minutes": minutes,
        "epochs": total,
        "valid_share": valid / max(total, 1),
        "mean_deg": float(e.mean()),
        "sd_deg": float(e.std()),
        "rms_deg": float(np.sqrt((e**2).mean())),
        "p95_abs_deg": float(np.percentile(abs(e), 95)),
        "model_fix_h_mm": noise.h_const_m * 1000,
        "model_fix_v_mm": noise.v_const_m * 1000,
        "model_ppm": noise.h_ppm,
        "model_baseline_km": rtk.baseline_m / 1000,
        "model_corr_s": noise.correlation_time_s,
        "compass_baseline_m": cfg.baseline_m,
        "predicted_sd_deg": math.degrees(
            math.sqrt(2) * (noise.h_const_m + noise.h_ppm * 1e-6 * rtk.baseline_m) / cfg.baseline_m
        ),
    }


def scan_timing(out: Path) -> dict[str, float]:
    layout, fld = load_field("engr")
    world = World(layout, fld)
    result = plan(layout)
    settings = ScanSettings()
    rng = np.random.default_rng(0)
    times, npts, labels = [], [], {name: 0 for name in LABEL_NAMES[1:]}
    for k, cid in enumerate(result.selected):
        j = fld.candidate_index(cid)
        s = world.settle(RobotState(x=float(fld.cand_xy[j, 0]), y=float(fld.cand_xy[j, 1])))
        t0 = time.perf_counter()
        scan = world.render_scan(world.scanner_pose(s), settings, rng)
        path = out / f"Scan_{k + 1:05d}.e57"
        write_e57(path, [PosedScan.as_scanned(scan.points, scan.intensity, path.stem)])
        times.append(time.perf_counter() - t0)
        npts.append(len(scan.points))
        for lab, name in enumerate(LABEL_NAMES[1:], start=1):
            labels[name] += int(np.count_nonzero(scan.label == lab))
    pts, _, _ = _read(out / "Scan_00001.e57")
    return {
        "scans": len(times),
        "first_scan_s": times[0],
        "mean_scan_s": float(np.mean(times[1:])),
        "mean_points": float(np.mean(npts)),
        "e57_points_read": len(pts),
        "rays_per_scan": int(settings_rays(settings)),
        **{f"points_{k}": v for k, v in labels.items()},
    }


def settings_rays(s: ScanSettings) -> float:
    return round((s.vertical_end_deg - s.vertical_start_deg) / s.step_deg) * round(
        (s.horizontal_end_deg - s.horizontal_start_deg) / s.step_deg
    )


def record_compass(bench: Bench, c: dict[str, float] | None, missing: str = "") -> None:
    """The compass figures; ``c`` None: not measured, ``missing`` says why."""
    models = {**rtk(RtkModelConfig()), **compass(Compass.of(default_robot())), "seed": "7"}

    def fig(name: str, key: str, unit: str, scale: float = 1.0, **kw: Any) -> None:
        v = None if c is None or key not in c else scale * c[key]
        bench.figure(f"GNSS compass: {name}", v, unit, error_models=models, missing=missing, **kw)

    predicted = "" if c is None else f"the error model predicts {c['predicted_sd_deg']:.2f} deg"
    fig("heading error SD against the true heading", "sd_deg", "deg", headline=True, note=predicted)
    fig("heading error mean", "mean_deg", "deg")
    fig("heading error RMS", "rms_deg", "deg")
    fig("heading error, 95 % below", "p95_abs_deg", "deg")
    fig("epochs with a valid heading (both antennas fixed)", "valid_share", "%", scale=100)


def record_scans(bench: Bench, s: dict[str, Any] | None, missing: str = "") -> None:
    """The FARO scan figures; ``s`` None: not measured, ``missing`` says why."""
    w = WorldConfig()
    models = faro(w.scanner_noise, 0.015)
    for name, key, unit in (
        ("time per scan of ENGR at 0.36 deg, incl. writing the E57", "mean_scan_s", "s"),
        ("first scan, incl. compilation", "first_scan_s", "s"),
        ("points per scan", "mean_points", ""),
    ):
        v = None if s is None or key not in s else float(s[key])
        bench.figure(
            f"simulated FARO: {name}",
            v,
            unit,
            error_models=models,
            missing=missing,
            headline=key == "mean_scan_s",
        )


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--minutes", type=float, default=10.0)
    args = ap.parse_args()
    bench = Bench("bench_devices")
    details: dict[str, Any] = {}
    try:
        c = compass_drive(args.minutes)
    except Exception as exc:  # its figures say not measured; the exit status fails
        why = f"{type(exc).__name__}: {exc}"
        bench.fail("compass", why)
        record_compass(bench, None, why)
    else:
        details["compass"] = c
        record_compass(bench, c)
        print_compass(c)
    try:
        with tempfile.TemporaryDirectory() as d:
            s = scan_timing(Path(d))
    except Exception as exc:
        why = f"{type(exc).__name__}: {exc}"
        bench.fail("scans", why)
        record_scans(bench, None, why)
    else:
        details["scans"] = s
        record_scans(bench, s)
        print_scans(s)
    return bench.finish(args.json, details)


def print_compass(c: dict[str, float]) -> None:
    print(
        f"GNSS compass over {c['minutes']:.0f} min of driving ({c['epochs']} epochs at 10 Hz, "
        f"{100 * c['valid_share']:.1f} % valid):"
    )
    print(
        f"  heading error mean {c['mean_deg']:+.3f} deg, SD {c['sd_deg']:.3f} deg, "
        f"RMS {c['rms_deg']:.3f} deg, 95 % below {c['p95_abs_deg']:.3f} deg"
    )
    print(
        f"  error model: Reach M2 fix {c['model_fix_h_mm']:.0f} mm + {c['model_ppm']:.0f} ppm "
        f"horizontal ({c['model_fix_v_mm']:.0f} mm vertical), base {c['model_baseline_km']:.1f} km"
        f", Gauss-Markov {c['model_corr_s']:.0f} s; baseline {c['compass_baseline_m']:.2f} m;"
        f" predicted SD {c['predicted_sd_deg']:.2f} deg"
    )


def print_scans(s: dict[str, Any]) -> None:
    print(
        f"FARO scans of ENGR at 0.36 deg ({s['rays_per_scan']:,} rays), {s['scans']} plan "
        f"locations: first {s['first_scan_s']:.2f} s (incl. compilation), then "
        f"{s['mean_scan_s']:.2f} s per scan incl. E57 writing; {s['mean_points']:,.0f} points "
        "per scan"
    )
    print(
        "  points by surface (all scans): "
        + ", ".join(f"{k[7:]} {v:,}" for k, v in s.items() if k.startswith("points_"))
    )


if __name__ == "__main__":
    sys.exit(main())
