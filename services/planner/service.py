"""The planner service's Zenoh shell: answers PlanRequests on ``rpc/planner/plan``.

Each request is planned in a worker process (:mod:`services.planner.pool`), so a long
plan (a 2,000-plot field) never holds up the answer to a short or cached one;
identical requests in flight share one computation; finished plans are cached. Before
anything reaches a worker, the request's field is built here and checked: a field
file outside the configured folders, or a field beyond the budget, gets an error reply
and costs the workers nothing.
"""

from __future__ import annotations

import collections
import threading
import time
from concurrent.futures import Future
from pathlib import Path

from common import keys
from common.field import FIELDS_DIR, FieldError, field_path
from common.field_model import scanner_model
from common.messages.plan import PlanRequest, PlanResult
from common.service import Context
from common.transport import RequestError
from services.planner.budget import check
from services.planner.config import PlannerConfig
from services.planner.pool import WorkerDied, WorkerPool
from services.planner.request import compute, request_key, resolve_field


def allowed_paths(ctx: Context, cfg: PlannerConfig) -> list[Path]:
    """Where a ``PlanRequest.name`` may point: ``cfg.field_dirs`` (default: the
    shipped examples and the run folder), plus the deployment's own field file."""
    dirs = [Path(d) for d in cfg.field_dirs] or [FIELDS_DIR, ctx.run_dir]
    try:
        own = field_path(ctx.field)
    except FieldError:
        return dirs
    return [*dirs, own]


class PlannerService:
    def __init__(self, ctx: Context, cfg: PlannerConfig) -> None:
        self.ctx, self.cfg = ctx, cfg
        self.allowed = allowed_paths(ctx, cfg)
        self.pool = WorkerPool(cfg.workers, cfg.budget.worker_memory_mb)
        self._lock = threading.Lock()
        self._cache: collections.OrderedDict[str, PlanResult] = collections.OrderedDict()
        self._inflight: dict[str, Future[PlanResult]] = {}
        ctx.bus.serve(keys.PLANNER_PLAN, self.handle)
        # plans being computed now, in the heartbeat (a plan takes seconds to minutes)
        ctx.bus.report("plans_computing", lambda: len(self._inflight))

    def handle(self, req: PlanRequest) -> PlanResult:
        try:  # fail fast, in this process, on a bad, forbidden or too large field
            _, fld = resolve_field(req, self.allowed)
            check(fld, self.cfg.budget, req.scanner.max_range)
        except FieldError as exc:
            raise RequestError(str(exc)) from None
        key = request_key(req)
        with self._lock:
            hit = self._cache.get(key)
            if hit is not None:
                self._cache.move_to_end(key)
                self.ctx.log.info("plan for %s served from cache", hit.field)
                return hit
            fut = self._inflight.get(key)
            if fut is None:
                fut = self.pool.submit(compute, req, None, self.cfg.budget, self.allowed)
                self._inflight[key] = fut
                self.ctx.log.info("planning %s (%d plots)", fld.name, fld.n_plots)
        t0 = time.monotonic()
        try:
            result = fut.result()
        except (FieldError, ValueError) as exc:
            raise RequestError(str(exc)) from None
        except MemoryError:
            raise RequestError(
                f"plan of {fld.name!r} ran out of the worker's memory limit "
                f"({self.cfg.budget.worker_memory_mb} MB, budget.worker_memory_mb)"
            ) from None
        except WorkerDied as exc:
            raise RequestError(f"plan of {fld.name!r} failed: {exc}") from None
        finally:
            with self._lock:
                self._inflight.pop(key, None)
        with self._lock:
            self._cache[key] = result
            while len(self._cache) > self.cfg.cache_size:
                self._cache.popitem(last=False)
        self.ctx.log.info(
            "planned %s: %d locations, %s tour %.1f m, in %.1f s",
            result.field,
            len(result.selected),
            result.tour.nav,
            result.tour.length,
            time.monotonic() - t0,
        )
        return result

    def run(self, stop: threading.Event) -> None:
        if self.cfg.warm_up:  # loads numba's kernels and caches the deployment's plan
            req = PlanRequest(
                name=self.ctx.field,
                scanner=scanner_model(self.ctx.robot),
                battery=self.ctx.robot.battery,
            )
            threading.Thread(target=self._warm_up, args=(req,), daemon=True).start()
        stop.wait()
        self.pool.close()

    def _warm_up(self, req: PlanRequest) -> None:
        try:
            self.handle(req)
        except RequestError as exc:
            self.ctx.log.warning("warm-up plan for %s failed: %s", req.name, exc)


def build(ctx: Context, cfg: PlannerConfig) -> PlannerService:
    return PlannerService(ctx, cfg)
