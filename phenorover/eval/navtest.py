"""``phenorover nav-test border|serpentine|stationary``: the paper's navigation
experiments on the simulated ENGR field, with real processes (sim, base, gnss, nav
from ``deploy/sim.toml``) and the simulator's default error models. Writes
``stats.json``, the effective manifest, and figures to the output folder."""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from common.config import load_manifest
from common.field import load_field
from common.messages.nav import (
    Leg,
    NavState,
)
from common.process import free_loopback_port
from common.transport import Bus
from phenorover.eval import experiments as ex
from phenorover.eval import profiles
from phenorover.eval.nav_recorder import Recorder, Release, follow, pace
from phenorover.eval.navtest_stationary import stationary

SERVICES = ("sim", "base", "gnss", "nav")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("experiment", choices=["border", "serpentine", "stationary"])
    p.add_argument("--manifest", type=Path, default=Path("deploy/sim.toml"))
    p.add_argument("--rtf", type=float, default=10.0, help="sim real-time factor")
    p.add_argument("--passes", type=int, default=2, help="serpentine: out-and-back passes")
    p.add_argument("--hold", type=float, default=420.0, help="stationary: seconds held (sim)")
    p.add_argument("--out", type=Path, default=None, help="output folder (runs/nav-EXPERIMENT)")
    p.add_argument("--seed", type=int, default=None, help="the world's and receivers' seed")
    p.add_argument(
        "--lockstep",
        action="store_true",
        help="run the world in lockstep with the services, held until the route is sent: "
        "the same seed gives the same run under any load (--rtf is then its cap)",
    )
    p.add_argument(
        "--profile",
        choices=sorted(profiles.PROFILES),
        default="ours",
        help="navigation: ours (the shipped defaults) or paper (the paper's method)",
    )


def _manifest(
    src: Path,
    rtf: float,
    out: Path,
    seed: int | None = None,
    profile: str = "ours",
    lockstep: bool = False,
) -> Path:
    with src.open("rb") as f:
        m: dict[str, Any] = profiles.apply(tomllib.load(f), profile)
    if seed is not None:
        m = profiles.seeded(m, seed)
    if lockstep:
        m["lockstep"] = True
    m["services"] = {k: v for k, v in m["services"].items() if k in SERVICES}
    m["services"].setdefault("sim", {})["real_time_factor"] = rtf
    # a private router port, so an experiment runs beside a deployment that is up
    m["zenoh"] = {**m.get("zenoh", {}), "listen": [f"tcp/127.0.0.1:{free_loopback_port()}"]}
    m["zenoh"].pop("connect", None)
    path = out / "manifest.toml"
    path.write_text(tomli_w.dumps(m))
    return path


def _figures(
    out: Path,
    xy: np.ndarray,
    xte: np.ndarray,
    t: np.ndarray,
    herr: np.ndarray,
    legs: list[Leg],
    title: str,
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(13, 5))
    for lg in legs:
        ax[0].plot([lg.x0, lg.x1], [lg.y0, lg.y1], color="0.75", lw=3, zorder=1)
    sc = ax[0].scatter(
        xy[:, 0], xy[:, 1], c=100 * np.abs(xte), s=4, cmap="viridis", vmin=0, vmax=10, zorder=2
    )
    fig.colorbar(sc, ax=ax[0], label="|cross-track error| (cm)")
    ax[0].set(aspect="equal", xlabel="x (m)", ylabel="y (m)", title=f"{title}: true path")
    ax[1].plot(t, np.degrees(herr), lw=0.8)
    ax[1].set(xlabel="sim time (s)", ylabel="heading error (deg)", title="heading error")
    fig.tight_layout()
    fig.savefig(out / f"{title}.png", dpi=120)
    plt.close(fig)


def run(args: argparse.Namespace) -> int:
    from common.client import open_client, wait_alive
    from phenorover.launcher import Launcher, held_world, release_world

    out = args.out or Path("runs") / f"nav-{args.experiment}"
    out.mkdir(parents=True, exist_ok=True)
    manifest = _manifest(args.manifest, args.rtf, out, args.seed, args.profile, args.lockstep)
    # in lockstep the world is held until the route is sent (nav then waits to be
    # localized on the world's time, not on this process's): the same seed, the same run
    held = held_world(manifest)
    launcher = Launcher(manifest, extra_args=held)
    with launcher, open_client(manifest, []) as session:
        bus = Bus(session, "nav-test")
        try:
            if not wait_alive(session, set(SERVICES), timeout=60):
                print("nav-test: services did not come up", file=sys.stderr)
                return 1
            rec = Recorder(bus)
            t0 = time.monotonic()
            while not held and not (rec.poses and rec.poses[-1].localized):
                if time.monotonic() - t0 > 120:
                    print("nav-test: never localized", file=sys.stderr)
                    return 1
                time.sleep(0.2)
            release = (lambda: release_world(bus)) if held else None
            stats = _experiment(args, bus, rec, out, release)
        finally:
            bus.close()
    # the models in force are those of the effective manifest beside this file (the
    # simulator's and receivers' defaults where it sets none)
    stats["error_models"] = str(manifest)
    stats["profile"] = args.profile
    (out / "stats.json").write_text(json.dumps(stats, indent=1))
    print(json.dumps(stats, indent=1))
    return 0


def add_command(p: argparse.ArgumentParser) -> None:
    """``phenorover nav-test``."""
    add_arguments(p)
    p.set_defaults(func=run)


def _experiment(
    args: argparse.Namespace, bus: Bus, rec: Recorder, out: Path, release: Release
) -> dict[str, Any]:
    _, fld = load_field(load_manifest(args.manifest).field)
    if args.experiment == "stationary":
        return stationary(args, bus, rec, out, fld, release)
    pts = (
        ex.border_points(fld)
        if args.experiment == "border"
        else ex.serpentine_points(fld, args.passes)
    )
    legs = ex.legs_through(pts)
    length = sum(math.hypot(lg.x1 - lg.x0, lg.y1 - lg.y0) for lg in legs)
    timeout = 60 + 20 * length / pace(args.rtf, release)
    ended = follow(bus, rec, legs, args.experiment, timeout=timeout, release=release)
    route = rec.paired(args.experiment)
    rows = [(t, p) for t, p in route if p.state == NavState.DRIVING]
    xy = np.array([[t.x, t.y] for t, _ in rows])
    yaw = np.array([t.yaw for t, _ in rows])
    legi = np.array([p.leg for _, p in rows], dtype=np.int64)
    ts = np.array([t.stamp_ns / 1e9 for t, _ in rows])
    xte, herr = ex.track_errors(xy, yaw, legi, legs)
    # what the follower steered on: the estimate's cross-track error at each sample;
    # the truth's less it is the estimate's own sideways error
    steered = np.array([p.cross_track for _, p in rows])
    # the samples themselves, for a look at where along the route the errors lie
    with rec.lock:
        est = np.array([[p.stamp_ns / 1e9, p.x, p.y, p.yaw] for p in rec.poses])
    np.savez_compressed(
        out / "track.npz",
        t=ts,
        xy=xy,
        yaw=yaw,
        leg=legi,
        xte=xte,
        herr=herr,
        steered=steered,
        est=est,
        # the whole route, every state: t, x, y, yaw, leg; and each sample's state
        route=np.array([[t.stamp_ns / 1e9, t.x, t.y, t.yaw, p.leg] for t, p in route]),
        states=np.array([p.state.value for _, p in route]),
    )
    _figures(out, xy, xte, ts, herr, legs, args.experiment)
    path = np.array([[t.x, t.y] for t, _ in route])  # the distance driven: the true path
    return {
        "experiment": args.experiment,
        "result": ended.state.value,
        "result_detail": ended.detail,
        "planned_route_m": length,
        "driven_true_m": ex.path_length(path),
        **ex.track_stats(xte, herr),
        "estimate_xte_mean_cm": float(100 * np.abs(steered).mean()),
        "estimate_lateral_error_mean_cm": float(100 * np.abs(xte - steered).mean()),
    }
