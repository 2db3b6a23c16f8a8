"""The error models in force, as one line each: printed beside every result.

Read from the config structs themselves (defaults, or a manifest's sections with its
overrides), so what is printed is what ran, never a copy of the README's table.
"""

from __future__ import annotations

from pathlib import Path

from common.config import decode_section, load_manifest
from common.robot import Robot, load_robot
from services.gnss.compass import Compass
from services.gnss.config import GnssConfig
from services.gnss.rtk_model import STATES, RtkModelConfig, StateNoise
from services.gnss.sim.config import ReachSimConfig
from services.sim.config import SimConfig
from services.sim.imu import ImuConfig
from services.sim.lidar import LidarConfig
from services.sim.render import FaroNoise
from services.sim.robot import RobotConfig
from services.sim.terrain import TerrainConfig
from services.sim.world_config import SoilZone


def _noise(n: StateNoise) -> str:
    return (
        f"{1000 * n.h_const_m:g} mm + {n.h_ppm:g} ppm horizontal, {1000 * n.v_const_m:g} mm + "
        f"{n.v_ppm:g} ppm vertical (1 sigma per axis), Gauss-Markov {n.correlation_time_s:g} s"
    )


def rtk(cfg: RtkModelConfig) -> dict[str, str]:
    """The simulated receivers: fix noise, float/single noise, the fix-state chain."""
    rates = cfg.rates_per_s
    dwell = [1.0 / sum(r for j, r in enumerate(row) if j != i) for i, row in enumerate(rates)]
    names = {s: s.name.lower().replace("_", " ") for s in STATES}
    return {
        "RTK fix": f"{_noise(cfg.fix)}, base {cfg.baseline_m:g} m away",
        "RTK float / single": (
            f"{cfg.float_.h_const_m:g} m / {cfg.single.h_const_m:g} m horizontal (1 sigma), "
            f"Gauss-Markov {cfg.float_.correlation_time_s:g} s / "
            f"{cfg.single.correlation_time_s:g} s"
        ),
        "RTK under the crop": (
            f"fix error x (1 + {cfg.canopy.noise_gain:g} x the share of the sky the plots "
            f"hide), fix lost x (1 + {cfg.canopy.float_gain:g} x that share)"
        ),
        "fix state chain": "mean dwell "
        + ", ".join(f"{names[s]} {d:.3g} s" for s, d in zip(STATES, dwell, strict=True))
        + f", starting in {names[cfg.initial_state]}",
    }


def compass(c: Compass) -> dict[str, str]:
    return {
        "GNSS compass": (
            f"two antennas {c.baseline_m:.2f} m apart, headings whose baseline is off by more "
            f"than {100 * c.baseline_tolerance_m:g} cm rejected"
        )
    }


def drive(robot: RobotConfig, soil: float, zones: list[SoilZone] | None = None) -> dict[str, str]:
    """Wheel slip and encoders (every slip term scales with ``soil``; ``zones`` have
    their own)."""
    where = "; ".join(
        f"soil {z.soil:g} over x {z.x_min:g}..{z.x_max:g}, y {z.y_min:g}..{z.y_max:g} m"
        for z in zones or []
    )
    return {
        **({"soil zones": where} if where else {}),
        "wheel slip": (
            f"{robot.slip_long * soil:.1%} forward slip; in-place turns reach "
            f"{robot.yaw_efficiency:.0%} of the wheel-implied rate, +-{robot.yaw_noise * soil:.0%}"
            f"/sqrt(Hz); turning centre wanders {100 * robot.icr_std * soil:.1f} cm "
            f"(tau {robot.icr_tau:g} s); lateral noise {robot.lateral_noise * soil:g} m/s per "
            f"m/s (soil factor {soil:g})"
        ),
        "encoders": (
            f"{robot.encoder_scale:.1%} scale error, {1000 * robot.encoder_v_std:g} mm/s and "
            f"{robot.encoder_w_std:g} rad/s noise"
        ),
    }


def terrain(cfg: TerrainConfig) -> dict[str, str]:
    return {
        "terrain": (
            f"{cfg.slope_pct:g} % slope rising towards {cfg.slope_dir_deg:g} deg, bumps "
            f"{100 * cfg.bump_rms:g} cm RMS over {cfg.bump_length:g} m"
        )
    }


def faro(noise: FaroNoise, inclinometer_sd_deg: float) -> dict[str, str]:
    return {
        "FARO ranging": (
            f"noise sigma^2 = ({noise.noise_floor_mm:g} mm)^2 + {noise.noise_slope_mm2_per_m:g} "
            "mm^2/m x range x (0.1 / reflectivity)^1.5, "
            f'+-{noise.range_bias_mm:g} mm ranging error, {noise.angle_sigma_arcsec:g}" angular'
        ),
        "FARO compensator": f"{inclinometer_sd_deg:g} deg (1 sigma)",
    }


def imu(cfg: ImuConfig) -> dict[str, str]:
    if not cfg.enabled:
        return {"IMU": "none"}
    return {
        "IMU (UM7 class)": (
            f"tilt bias {cfg.tilt_bias_sd_deg:g} deg per axis per run, noise "
            f"{cfg.tilt_noise_sd_deg:g} deg, {cfg.accel_leak:g} of a/g read as tilt, "
            f"{cfg.rate_hz:g} Hz"
        )
    }


def lidar(cfg: LidarConfig) -> dict[str, str]:
    return {
        "2D lidar": (
            f"{cfg.fov_deg:g} deg, {cfg.step_deg:g} deg steps, {cfg.min_range:g}-"
            f"{cfg.max_range:g} m, sigma {1000 * cfg.sigma:g} mm"
        )
    }


def simulation(
    sim: SimConfig, gnss: GnssConfig, robot: Robot, reach: ReachSimConfig | None = None
) -> dict[str, str]:
    """Every model of a simulated deployment, with the seeds that drew them; the RTK
    model only where the receivers are simulated: by the gnss ``sim`` backend, or by
    ``reach`` (the simulated Reach M2s a hardware-in-the-loop deployment reads)."""
    w = sim.world
    receivers = reach if reach is not None else gnss if gnss.backend == "sim" else None
    return {
        **(rtk(receivers.rtk) if receivers is not None else {}),
        **compass(Compass.of(robot, gnss.compass)),
        **drive(w.robot, w.soil, w.soil_zones),
        **terrain(w.terrain),
        **faro(w.scanner_noise, sim.inclinometer_sd_deg),
        **imu(sim.imu),
        **lidar(w.lidar),
        "seeds": f"sim noise {sim.seed}, world (terrain, plants) {w.seed}, receivers "
        f"{(receivers or gnss).seed}",
    }


def from_manifest(path: Path) -> dict[str, str]:
    """The models of the deployment ``path`` describes (its sim and gnss sections over
    the defaults, its robot description). Raises common.config.ConfigError on a bad
    manifest or robot description."""
    m = load_manifest(path)
    sim = decode_section(m.services.get("sim", {}), SimConfig, "[services.sim]")
    gnss_section = m.services.get("gnss", {"backend": "sim"})
    gnss = decode_section(gnss_section, GnssConfig, "[services.gnss]")
    reach_section = m.services.get("reach-sim")
    reach = (
        None
        if reach_section is None
        else decode_section(reach_section, ReachSimConfig, "[services.reach-sim]")
    )
    return simulation(sim, gnss, load_robot(m.robot), reach)
