"""The planner worker: the missions' slow plans (transport local plan, object route,
re-arrangement set, capture re-plan) run here, off the control loop (ARCHITECTURE "Time").

One worker thread runs the jobs in submission order, so what a job owns (a planner's warm start,
its generator) is never touched by two at once, and the tick never waits on a planner:

- **lab** (``lockstep=False``): a result is ready as soon as it is computed; a job that takes
  longer than its kind's budget (``planner.latency_ticks`` ticks) is counted ``late``; one that
  takes longer than ``planner.timeout`` is given up (the mission holds the robots safely);
- **lockstep dry run** (``lockstep=True``): a plan asked for at sim time t is ready at exactly
  t + ``latency_ticks`` ticks, whatever the wall clock did (the worker computes meanwhile; the
  tick that picks the plan up waits for it if it is not done yet, and ``waiting`` tells the sim
  side so). The same seed gives the same run on an idle or a loaded machine.

Thread, not process: the jobs share the mission's planner objects (warm starts, caches) without
a copy, and the GIL's cost to the tick is measured by ``bench/loop.py`` (``planner_busy``).
Latencies (wall s from submit to result) are kept per kind for ``fleet status`` and the run
summary (``plan_latency_s``).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Mapping
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from controller.mission.planners import PLANNER_KINDS, PlanResult, run_job

log = logging.getLogger(__name__)


@dataclass
class _Job:
    kind: str
    t: float  # tick time it was asked for (s)
    due: float  # tick time it is ready at (lockstep)
    wall: float  # clock() at submit
    future: Future
    done_wall: float | None = None


@dataclass
class KindStats:
    latencies: list[float] = field(default_factory=list)  # wall s, submit to result
    late: int = 0  # results that took longer than the kind's budget
    timeouts: int = 0
    failed: int = 0
    waited_s: float = 0.0  # lockstep: wall s the tick waited for a due plan

    def summary(self) -> dict[str, Any]:
        a = np.asarray(self.latencies)
        return {
            "n": len(a),
            "p50": float(np.median(a)) if len(a) else None,
            "p99": float(np.percentile(a, 99)) if len(a) else None,
            "max": float(a.max()) if len(a) else None,
            "late": self.late,
            "timeouts": self.timeouts,
            "failed": self.failed,
            "waited_s": round(self.waited_s, 6),
        }


class PlannerWorker:
    """The :class:`controller.mission.planners.Planners` port behind the lab daemon and the
    dry run. ``latency_ticks``: per kind, the plan latency budget in ticks of ``dt`` s (the
    modelled latency in lockstep); ``timeout``: wall s after which a lab job is given up."""

    def __init__(
        self,
        latency_ticks: Mapping[str, int],
        dt: float,
        lockstep: bool,
        timeout: float = 10.0,
        clock: Callable[[], float] = time.perf_counter,
    ) -> None:
        self.latency_ticks = dict(latency_ticks)
        self.dt = dt
        self.lockstep = lockstep
        self.timeout = timeout
        self.clock = clock
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="planner")
        self._jobs: dict[int, _Job] = {}
        self._next = 0
        self._lock = threading.Lock()
        self.stats = {k: KindStats() for k in PLANNER_KINDS}
        self._waiting = threading.Event()

    @property
    def waiting(self) -> bool:
        """Whether the tick is waiting for a plan due now (lockstep)."""
        return self._waiting.is_set()

    def budget(self, kind: str) -> float:
        """The kind's latency budget, s."""
        return self.latency_ticks.get(kind, 0) * self.dt

    def submit(self, kind: str, t: float, fn: Callable[..., Any], *args: Any) -> int:
        with self._lock:
            self._next += 1
            ticket = self._next
        due = t + self.latency_ticks.get(kind, 0) * self.dt - 1e-9
        job = _Job(kind, t, due, self.clock(), Future())
        job.future = self._pool.submit(self._run, job, fn, args)
        self._jobs[ticket] = job
        return ticket

    def _run(self, job: _Job, fn: Callable[..., Any], args: tuple[Any, ...]) -> PlanResult:
        res = run_job(fn, args)
        job.done_wall = self.clock()
        return res

    def poll(self, ticket: int, t: float) -> PlanResult | None:
        job = self._jobs.get(ticket)
        if job is None:
            return None
        if self.lockstep:
            if t < job.due:
                return None
            res = self._wait(job)
        elif job.future.done():
            res = job.future.result()
        elif self.clock() - job.wall > self.timeout:
            self.stats.setdefault(job.kind, KindStats()).timeouts += 1
            del self._jobs[ticket]
            log.error("the %s planner gave no plan in %.1f s: given up", job.kind, self.timeout)
            return PlanResult(False, error=f"timeout after {self.timeout:g} s")
        else:
            return None
        del self._jobs[ticket]
        self._account(job, res)
        return res

    def _wait(self, job: _Job) -> PlanResult:
        if job.future.done():
            return job.future.result()
        start = self.clock()
        self._waiting.set()
        try:
            return job.future.result()
        finally:
            self._waiting.clear()
            self.stats.setdefault(job.kind, KindStats()).waited_s += self.clock() - start

    def _account(self, job: _Job, res: PlanResult) -> None:
        s = self.stats.setdefault(job.kind, KindStats())
        latency = (job.done_wall or self.clock()) - job.wall
        s.latencies.append(latency)
        s.failed += not res.ok
        budget = self.budget(job.kind)
        if budget > 0 and latency > budget:
            s.late += 1  # lockstep: the tick waited for it (waited_s); the lab: it came late
            if not self.lockstep and (s.late == 1 or s.late % 20 == 0):
                log.warning(
                    "a %s plan took %.0f ms, over its %.0f ms budget (%d late so far)",
                    job.kind,
                    latency * 1e3,
                    budget * 1e3,
                    s.late,
                )

    def discard(self, ticket: int) -> None:
        # the job still runs (never cancelled): whether a job ran must not depend on timing,
        # it may change what later jobs start from (a warm start, a solver's workspace)
        self._jobs.pop(ticket, None)

    def summary(self) -> dict[str, dict[str, Any]]:
        """Per kind that ran: latency p50/p99/max (wall s), late, timeouts, failed, waited."""
        return {k: s.summary() for k, s in self.stats.items() if s.latencies or s.timeouts}

    @classmethod
    def for_config(cls, cfg, lockstep: bool) -> PlannerWorker:
        """The worker of a config (``[planner]``, ``fleet.rate_hz``): lockstep for the dry run."""
        return cls(
            cfg.planner.latency_ticks(),
            cfg.fleet.period,
            lockstep=lockstep,
            timeout=cfg.planner.timeout,
        )

    def close(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)
