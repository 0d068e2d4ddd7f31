"""Planning off the control tick: the port through which a mission asks for a plan and picks
it up on a later tick (docs/architecture.md, "Time": the control tick never waits on a planner).

A mission never calls a slow planner itself. It ``submit``s a job (a pure function and its
arguments) and ``poll``s for the result on the ticks that follow; meanwhile it executes the
latest valid plan re-anchored to the current estimate, or holds the robots safely. What stands
behind the port decides when a result is ready:

- :class:`InlinePlanners` (here; unit tests and offline tools): computed at ``submit``, ready at
  once, the old synchronous behaviour;
- ``runtime.planner.PlannerWorker`` (the lab daemon and the dry run): a worker off the loop;
  ready when computed (lab), or exactly ``latency_ticks`` ticks after the request in sim time
  (lockstep dry run: the same seed gives the same run on an idle or a loaded machine).

Jobs run one at a time in submission order, so the state a job owns (a planner's warm start,
the generator it is handed) is never touched by two at once. A job's generator is spawned from
the mission's at submission (``spawn_rng``): the tick and the worker never share one.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

# the planners a mission runs off the tick (``fleet status`` and the run summary report each)
PLANNER_KINDS = ("transport", "route", "rearrange", "capture", "detour")


class JobOwned:
    """A box for state that only jobs touch (a planner's warm start, its caches): the mission
    hands the box to its jobs and never reads or writes ``value`` itself. A worker in another
    process keeps its own copy, sent once, so the state lives where the jobs run."""

    def __init__(self, value: Any = None) -> None:
        self.value = value

    def built(self, make: Callable[[], Any]) -> Any:
        """The value, made by ``make()`` first when there is none (a job's lazy state)."""
        if self.value is None:
            self.value = make()
        return self.value


@dataclass(frozen=True)
class PlanResult:
    """A finished job: ``ok`` with its ``value``, or not with the ``error`` (an exception's
    text, or ``timeout``)."""

    ok: bool
    value: Any = None
    error: str = ""


class Planners(Protocol):
    """The port a mission plans through. ``t``: the sim or wall time of the tick (s)."""

    def submit(self, kind: str, t: float, fn: Callable[..., Any], *args: Any) -> int: ...

    def poll(self, ticket: int, t: float) -> PlanResult | None:
        """The job's result once it is ready at tick time ``t`` (None: still pending)."""
        ...

    def discard(self, ticket: int) -> None:
        """Forget a job whose result is no longer wanted (it may still run to its end)."""
        ...


def run_job(fn: Callable[..., Any], args: tuple[Any, ...]) -> PlanResult:
    """Run one job; an exception becomes a failed result (a planner never kills the loop)."""
    try:
        return PlanResult(True, fn(*args))
    except Exception as exc:  # noqa: BLE001 - reported to the mission as a failed plan
        return PlanResult(False, error=f"{type(exc).__name__}: {exc}")


class InlinePlanners:
    """Every job computed at ``submit`` and ready at once (latency 0)."""

    def __init__(self) -> None:
        self._results: dict[int, PlanResult] = {}
        self._next = 0

    def submit(self, kind: str, t: float, fn: Callable[..., Any], *args: Any) -> int:
        self._next += 1
        self._results[self._next] = run_job(fn, args)
        return self._next

    def poll(self, ticket: int, t: float) -> PlanResult | None:
        return self._results.pop(ticket, None)

    def discard(self, ticket: int) -> None:
        self._results.pop(ticket, None)


class DeferredPlanners:
    """Every job computed at ``submit`` and ready ``latency_ticks`` ticks of ``dt`` s later in
    tick time: the lockstep worker's results, without a thread (the replay of a dry run's log;
    jobs run in the same order, so the results are the same)."""

    def __init__(self, latency_ticks: dict[str, int], dt: float) -> None:
        self.latency_ticks = dict(latency_ticks)
        self.dt = dt
        self._jobs: dict[int, tuple[float, PlanResult]] = {}
        self._next = 0

    @classmethod
    def for_config(cls, cfg) -> DeferredPlanners:
        return cls(cfg.planner.latency_ticks(), cfg.fleet.period)

    def submit(self, kind: str, t: float, fn: Callable[..., Any], *args: Any) -> int:
        self._next += 1
        due = t + self.latency_ticks.get(kind, 0) * self.dt - 1e-9
        self._jobs[self._next] = (due, run_job(fn, args))
        return self._next

    def poll(self, ticket: int, t: float) -> PlanResult | None:
        job = self._jobs.get(ticket)
        if job is None or t < job[0]:
            return None
        del self._jobs[ticket]
        return job[1]

    def discard(self, ticket: int) -> None:
        self._jobs.pop(ticket, None)


class PlanSlot:
    """One outstanding job of one kind for a mission: request, then take on a later tick."""

    def __init__(self, planners: Planners, kind: str) -> None:
        self.planners = planners
        self.kind = kind
        self.ticket: int | None = None
        self.requested_t: float | None = None

    @property
    def pending(self) -> bool:
        return self.ticket is not None

    def request(self, t: float, fn: Callable[..., Any], *args: Any) -> None:
        """Ask for a plan (a pending one of this slot is dropped first)."""
        self.cancel()
        self.ticket = self.planners.submit(self.kind, t, fn, *args)
        self.requested_t = t

    def take(self, t: float) -> PlanResult | None:
        """The result once ready (the slot is free again), else None."""
        if self.ticket is None:
            return None
        res = self.planners.poll(self.ticket, t)
        if res is not None:
            self.ticket = None
        return res

    def cancel(self) -> None:
        if self.ticket is not None:
            self.planners.discard(self.ticket)
            self.ticket = None


def spawn_rng(rng: np.random.Generator) -> np.random.Generator:
    """A job's own generator, drawn from the mission's (deterministic, independent)."""
    return rng.spawn(1)[0]
