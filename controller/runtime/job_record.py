"""What ``fleet daemon`` knows of its job at the end, as the ``--json``-shaped dict
``controller.outcome`` reads: the phases it went through, the failure (its reason and detail,
from the mission's ``failure`` event), the arrest, the delivery (the estimated pose at the goal)
and the mission's own figures. The daemon ticks on the wall clock: every instant is kept in
epoch seconds with ``t0_s``, the job's start, beside them (the outcome prints them relative)."""

from __future__ import annotations

import math
from typing import Any

from controller.config import FleetConfig
from controller.events import ArrestEvent, DeliveredEvent, FailureEvent
from controller.mission.summary import summary_of
from controller.runtime.summary import limits_of

CARRIED = ("route", "rearrange", "transport")  # the phases in which the object is carried


class JobRecord:
    """Fed every tick's mission output (``tick``); ``summary`` at the end."""

    def __init__(self, cfg: FleetConfig, t0: float) -> None:
        self.cfg = cfg
        self.t0 = t0
        self.phases: list[dict[str, Any]] = []
        self.failure: dict[str, Any] | None = None
        self.arrest_t: float | None = None
        self.delivered: list[float] | None = None  # the object's estimated pose at the goal
        self.done = False
        self.last = 0.0

    @property
    def phase(self) -> str | None:
        """The last phase the job was in before it failed (or its current one)."""
        words = [p["phase"] for p in self.phases if p["phase"] != "failed"]
        return words[-1] if words else None

    def tick(self, now: float, out: Any) -> None:
        """One tick's ``MissionOutput`` (or a ``TickResult`` with ``phase``, ``events``,
        ``done``, ``failed``, ``reason``) at wall time ``now``."""
        self.last = now
        phase = str(getattr(out, "phase", "") or "")
        if phase and (not self.phases or self.phases[-1]["phase"] != phase):
            self.phases.append({"phase": phase, "t": now})
        for ev in getattr(out, "events", None) or []:
            if isinstance(ev, ArrestEvent) and self.arrest_t is None:
                self.arrest_t = now
            elif isinstance(ev, DeliveredEvent):
                self.delivered = [float(v) for v in ev.pose]
            elif isinstance(ev, FailureEvent) and self.failure is None:
                self.failure = {"reason": str(ev.reason), "t": now, "detail": ev.detail}
        if getattr(out, "failed", False) and self.failure is None:
            reason = getattr(out, "reason", "") or "failed"
            self.failure = {"reason": str(reason), "t": now, "detail": ""}
        self.done |= bool(getattr(out, "done", False))

    def summary(self, mission: Any, stopped: str | None, end: float, **extra: Any) -> dict:
        """The outcome's dict: ``stopped`` says why a job that neither finished nor failed
        ended (interrupted, ``--duration``, taken over); ``extra`` adds figures (the log, the
        plan latencies)."""
        figures = summary_of(mission).to_json()
        out: dict[str, Any] = {
            "t0_s": self.t0,
            "start_s": self.t0,
            "duration_s": round(end - self.t0, 3),
            "status": "failed" if self.failure else ("ok" if self.done else None),
            "phase": "failed" if self.failure else self.phase,
            "mission_phase": self.phase,
            "failure": self.failure,
            "stopped": None if (self.failure or self.done) else (stopped or "stopped"),
            "phases": self.phases,
            "arrested": self.arrest_t is not None,
            "arrest_time_s": self.arrest_t,
            "arrival_spread_s": figures.get("arrival_spread_s"),
            **self._transport(figures),
            **limits_of(self.cfg),
            "config": self.cfg.source,
        }
        out.update(extra)
        return out

    def _transport(self, figures: dict[str, Any]) -> dict[str, Any]:
        goal = self.cfg.object.goal
        if goal is None:
            return {"transported": None}
        out: dict[str, Any] = {"transported": self.delivered is not None}
        if self.delivered is not None:
            dx, dy = self.delivered[0] - goal[0], self.delivered[1] - goal[1]
            dth = math.remainder(self.delivered[2] - goal[2], math.tau)
            out["goal_error_m"] = math.hypot(dx, dy)
            out["goal_error_deg"] = abs(math.degrees(dth))
        start = next((p["t"] for p in self.phases if p["phase"] in CARRIED), None)
        end = next((p["t"] for p in self.phases if p["phase"] in ("done", "failed")), None)
        if start is not None and end is not None:
            out["transport_time_s"] = round(end - start, 3)
        for k in ("route_length_m", "planned_force_mean_n", "rearrangements", "relocations"):
            if figures.get(k) is not None:
                out[k] = figures[k]
        return out
