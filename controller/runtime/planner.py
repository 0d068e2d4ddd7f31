"""The planner worker: the missions' slow plans (transport local plan, object route,
re-arrangement set, capture re-plan, the approach's detours) run here, off the control loop
(docs/architecture.md, "Time").

One worker thread runs the jobs in submission order, so what a job owns (a planner's warm start,
its generator) is never touched by two at once, and the tick never waits on a planner:

- **lab** (``lockstep=False``): a result is ready as soon as it is computed; a job that takes
  longer than its kind's budget (``planner.latency_ticks`` ticks) is counted ``late``; one that
  takes longer than ``planner.timeout`` is given up (the mission holds the robots safely);
- **lockstep dry run** (``lockstep=True``): a plan asked for at sim time t is ready at exactly
  t + ``latency_ticks`` ticks, whatever the wall clock did (the worker computes meanwhile; the
  tick that picks the plan up waits for it if it is not done yet, and ``waiting`` tells the sim
  side so). The same seed gives the same run on an idle or a loaded machine.

A process, not a thread (``process=True``, the default): a planner in a thread of the daemon
holds the GIL for most of its run, and the control tick, which needs it too, came out late by
50-165 ms at 20 Hz during every transport plan in the lab rehearsal (``bench/loop.py`` measures
both). The state only jobs touch (``JobOwned``: a planner's warm start, the route planner's
tables) is sent to the worker process once and lives there; each job sends its inputs (a few
kB) and gets its plan back. Jobs are pure functions of those, in submission order: the worker
computes what an in-process run would (``DeferredPlanners`` replays a dry run's log exactly).
Latencies (wall s from submit to result) are kept per kind for ``fleet status`` and the run
summary (``plan_latency_s``). The worker is spawned, never forked (the daemon has zenoh's
threads): a script that builds one must guard its top level with ``if __name__ ==
"__main__":`` as multiprocessing asks (the ``fleet`` entry point and the benches do).
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import threading
import time
from collections.abc import Callable, Mapping
from concurrent.futures import Executor, Future, ProcessPoolExecutor, ThreadPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from controller.mission.planners import PLANNER_KINDS, JobOwned, PlanResult, run_job

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class _Ref:
    """A ``JobOwned`` box as a job's argument: its token, and the box itself the first time."""

    token: int
    box: JobOwned | None


_OWNED: dict[int, JobOwned] = {}  # in the worker process: the boxes sent so far, by token


def _run_owned(fn: Callable[..., Any], args: tuple[Any, ...]) -> PlanResult:
    """A job in the worker process, its boxes resolved to the worker's own copies."""
    real = []
    for a in args:
        if isinstance(a, _Ref):
            if a.box is not None:
                _OWNED[a.token] = a.box
            if a.token not in _OWNED:
                return PlanResult(False, error="the planner worker lost its state (restarted?)")
            a = _OWNED[a.token]
        real.append(a)
    return run_job(fn, tuple(real))


# the worker's niceness: below the control loop, the world and the agents on the same cores.
# A transport plan keeps the worker busy for most of each interval; at the same priority it
# took a core the loop needed (the README lab on 2 cores: tick p50 32.9 ms, p99 81.6 ms at
# 20 Hz, 7 % of ticks late). A plan that comes later is held safely; a late tick is not.
WORKER_NICE = 10


def _follow_parent(parent: int, period: float = 0.5) -> None:
    """In the worker process: run below the loop (``WORKER_NICE``), and end when the process
    that started it is gone (a daemon killed with SIGKILL never shuts its pool down: its worker
    would live on, orphaned)."""
    os.nice(WORKER_NICE)

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(period)  # a poll of the parent's pid, not a wait for anything
        os._exit(0)

    threading.Thread(target=watch, name="follow-parent", daemon=True).start()


def _warm() -> None:
    """Import the planners in the worker before the first job needs them."""
    import controller.mission.job  # noqa: F401
    import controller.mission.transport  # noqa: F401


# s to wait for the process pool's thread once its worker is terminated (it ends at once)
CLOSE_JOIN_S = 5.0

# times one job is run again on a restarted worker after the worker died under it (a job that
# kills its worker every time is then a failed plan, not a restart loop)
JOB_RETRIES = 1


@dataclass
class _Job:
    kind: str
    t: float  # tick time it was asked for (s)
    due: float  # tick time it is ready at (lockstep)
    wall: float  # clock() at submit
    future: Future
    done_wall: float | None = None
    fn: Callable[..., Any] | None = None  # the job, kept to run it again on a restarted worker
    args: tuple[Any, ...] = ()
    generation: int = 0  # the worker process it was sent to
    retries: int = 0


@dataclass
class KindStats:
    latencies: list[float] = field(default_factory=list)  # wall s, submit to result
    late: int = 0  # results that took longer than the kind's budget
    timeouts: int = 0
    failed: int = 0
    waited_s: float = 0.0  # lockstep: wall s the tick waited for a due plan
    restarts: int = 0  # jobs of this kind run again after the worker died under them

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
            "restarts": self.restarts,
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
        process: bool = True,
    ) -> None:
        self.latency_ticks = dict(latency_ticks)
        self.dt = dt
        self.lockstep = lockstep
        self.timeout = timeout
        self.clock = clock
        self.process = process
        self._pool: Executor = self._start_pool()
        self.generation = 0  # worker processes started after the first (restarts)
        self._tokens: dict[int, tuple[int, JobOwned]] = {}  # id(box) -> (token, box)
        self._jobs: dict[int, _Job] = {}
        self._next = 0
        self._lock = threading.RLock()  # _revive sends under it
        self.stats = {k: KindStats() for k in PLANNER_KINDS}
        self._waiting = threading.Event()

    def _start_pool(self) -> Executor:
        if not self.process:
            return ThreadPoolExecutor(max_workers=1, thread_name_prefix="planner")
        ctx = multiprocessing.get_context("spawn")  # never fork a process with threads
        pool = ProcessPoolExecutor(
            max_workers=1, mp_context=ctx, initializer=_follow_parent, initargs=(os.getpid(),)
        )
        pool.submit(_warm)
        return pool

    def _send(self, job: _Job) -> None:
        """Submit ``job`` to the current worker (its boxes as tokens once sent); a worker found
        dead at submit (it died under an earlier job) is restarted first."""
        with self._lock:
            try:
                self._submit(job)
            except BrokenProcessPool:
                self._restart(job.kind)
                self._submit(job)
            job.generation = self.generation
        job.future.add_done_callback(lambda _: setattr(job, "done_wall", self.clock()))

    def _submit(self, job: _Job) -> None:
        if self.process:
            refs = tuple(self._ref(a) for a in job.args)
            job.future = self._pool.submit(_run_owned, job.fn, refs)
        else:
            job.future = self._pool.submit(run_job, job.fn, job.args)

    def _restart(self, kind: str) -> None:
        """A new worker process in place of the dead one (what it held is lost: each box is
        sent whole again, as the mission left it)."""
        self._pool.shutdown(wait=False, cancel_futures=True)
        self._pool = self._start_pool()
        self.generation += 1
        self._tokens.clear()
        log.error(
            "the planner worker died (a %s plan was running): restarted (%d so far); its plans "
            "run again, their warm starts lost",
            kind,
            self.generation,
        )

    def _revive(self, job: _Job) -> None:
        """The worker died under ``job``: a new one (once per death: the other jobs sent to
        the dead one only resend) runs the job again."""
        with self._lock:
            if job.generation == self.generation:
                self._restart(job.kind)
            job.retries += 1
            job.wall, job.done_wall = self.clock(), None
            self.stats.setdefault(job.kind, KindStats()).restarts += 1
            self._send(job)

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
        job = _Job(kind, t, due, self.clock(), Future(), fn=fn, args=args)
        self._send(job)
        self._jobs[ticket] = job
        return ticket

    def _ref(self, arg: Any) -> Any:
        """A box as its token (sent whole the first time); any other argument as it is."""
        if not isinstance(arg, JobOwned):
            return arg
        known = self._tokens.get(id(arg))
        if known is not None and known[1] is arg:
            return _Ref(known[0], None)
        token = len(self._tokens) + 1
        self._tokens[id(arg)] = (token, arg)  # (the box is kept: its id is never reused)
        return _Ref(token, arg)

    def poll(self, ticket: int, t: float) -> PlanResult | None:
        job = self._jobs.get(ticket)
        if job is None:
            return None
        if self.lockstep:
            if t < job.due:
                return None
            res = self._wait(job)
        elif job.future.done():
            res = self._result(job)
            if res is None:  # the worker died: the job runs again on a new one
                return None
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
            res = self._result(job)
            if res is not None:
                return res
        start = self.clock()
        self._waiting.set()
        try:
            while (res := self._result(job)) is None:  # the worker died: wait for the rerun
                pass
            return res
        finally:
            self._waiting.clear()
            self.stats.setdefault(job.kind, KindStats()).waited_s += self.clock() - start

    def _result(self, job: _Job) -> PlanResult | None:
        """The job's result (waiting for it); None when its worker died and the job was sent
        to a new one (``JOB_RETRIES`` times at most, then a failed plan)."""
        try:
            return job.future.result()
        except BrokenProcessPool as exc:
            if job.retries < JOB_RETRIES:
                self._revive(job)
                return None
            return PlanResult(False, error=f"the planner worker died running it: {exc!r}")
        except Exception as exc:  # noqa: BLE001 - a pickling error, a cancelled job
            return PlanResult(False, error=f"the planner worker failed: {exc!r}")

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
    def for_config(cls, cfg, lockstep: bool, process: bool = True) -> PlannerWorker:
        """The worker of a config (``[planner]``, ``fleet.rate_hz``): lockstep for the dry run."""
        return cls(
            cfg.planner.latency_ticks(),
            cfg.fleet.period,
            lockstep=lockstep,
            timeout=cfg.planner.timeout,
            process=process,
        )

    def close(self) -> None:
        """End the worker now: queued jobs cancelled, a plan still running abandoned (its
        process terminated, not waited for), the pool's thread joined. A pool only told to shut
        down kept the interpreter's exit waiting for the running plan, then could print
        ``OSError: Bad file descriptor`` from ``concurrent.futures`` (its exit hook woke a
        thread that was closing its pipe)."""
        pool = self._pool
        procs = list((getattr(pool, "_processes", None) or {}).values())
        manager = getattr(pool, "_executor_manager_thread", None)
        pool.shutdown(wait=False, cancel_futures=True)
        for p in procs:
            if p.is_alive():
                p.terminate()
        if manager is not None:
            manager.join(timeout=CLOSE_JOIN_S)
