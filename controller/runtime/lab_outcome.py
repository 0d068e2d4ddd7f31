"""How a ``fleet up`` lab ended, for a person and for ``--json``: the job's verdict read from the
daemon's MCAP (``fleet replay``'s figures, judged from the world's truth when rehearsing), or
the lab's own reason when it ended before the job did (a part not ready, the world gone, the
operator's stop)."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from controller.runtime.lab import Lab


def _job_figures(log: Path) -> dict[str, Any] | None:
    """``fleet replay --json``'s object for the daemon's log (None when there is none)."""
    if not log.exists() or log.stat().st_size == 0:
        return None
    from controller.replay.log import load_run, metrics_of

    try:
        return metrics_of(load_run(log))
    except Exception as exc:  # noqa: BLE001 - a log that cannot be read: say so, keep going
        return {"error": f"the daemon's log could not be read: {exc}"}


def lab_outcome(lab: Lab, daemon_code: int | None, interrupted: bool) -> dict[str, Any]:
    """The lab's end as one JSON-ready object: ``status`` ("ok", "failed", "stopped"),
    ``exit`` (0, 1), ``verdict`` (one line), ``reason``, the run folder and log, bring-up
    time, restarts, and ``job`` (the replay's figures of the daemon's log)."""
    from controller import outcome

    log = lab.run_dir / "daemon.mcap"
    job = _job_figures(log)
    restarts = {p.name: p.restarts for p in lab.parts if p.restarts}
    base = {
        "run_dir": str(lab.run_dir),
        "log": str(log) if log.exists() else None,
        "ready_s": None if lab.ready_s is None else round(lab.ready_s, 1),
        "restarts": restarts,
        "daemon_exit": daemon_code,
        "job": job,
    }
    if lab.failure is not None:
        status, reason = "failed", lab.failure
        verdict = f"FAILED before the job ended: {lab.failure}"
    elif interrupted and daemon_code is None:
        status, reason = "stopped", "interrupted"
        phase = _last_phase(job)
        verdict = "STOPPED by the operator" + (f" in phase {phase}" if phase else "")
        if lab.resumed_at is not None and lab.stopped_at is not None:
            verdict += f", {lab.stopped_at - lab.resumed_at:.0f} s after the resume"
        else:
            verdict += ", before any resume"
        verdict += "; " + _estop_words(lab.final_estop)
    else:
        summary = dict(job or {})
        if daemon_code not in (0, None):
            summary.setdefault("status", "failed")
        # the daemon's exit says what the controller believed; the log's figures, judged from
        # the world's truth when rehearsing, may still find a failure (robots that touched)
        judged = outcome.failure_of({k: v for k, v in summary.items() if k != "status"})
        status = "ok" if daemon_code == 0 and judged is None else "failed"
        summary["status"] = status
        reason = (summary.get("failure") or {}).get("reason") if status != "ok" else None
        verdict = outcome.verdict_line(summary)
        if lab.ready_s is not None:
            verdict += f"; the lab up in {lab.ready_s:.0f} s"
    return {
        "status": status,
        "exit": 0 if status == "ok" else 1,
        "verdict": verdict,
        "reason": reason,
        **base,
    }


def _estop_words(result: dict[str, Any] | None) -> str:
    """How the e-stop at the lab's end went, in a few words."""
    if result is None:
        return "the e-stop could not be put (no bus): the agents' watchdogs stopped the robots"
    missing = result.get("agents_missing") or []
    if missing:
        return f"e-stop NOT confirmed by {', '.join(missing)} (their watchdogs stop them)"
    if result.get("durable") is False:
        return (
            f"every robot e-stopped, but {', '.join(result.get('not_durable') or [])} could not "
            "keep the e-stop in the state folder"
        )
    return f"every robot e-stopped (confirmed by all {len(result['agents_confirmed'])} agents)"


def _last_phase(job: dict[str, Any] | None) -> str:
    """The job's last phase in the log ("" when it logged none)."""
    phases = (job or {}).get("phases") or []
    if phases and isinstance(phases[-1], dict):
        return str(phases[-1].get("phase", ""))
    return ""


def print_outcome(result: dict[str, Any], as_json: bool) -> None:
    """The verdict line, the job's figures, the next step; or one JSON object."""
    from controller import outcome

    if as_json:
        sys.stdout.write(json.dumps(result, default=str, allow_nan=False) + "\n")
        return
    print(result["verdict"])
    job = result.get("job")
    if job and "error" not in job:
        print(outcome.outcome_table(job))
    print("next:")
    for step in outcome.next_steps(job or {}, result.get("log")):
        print(f"  {step}")
    print(f"  every part's log: {result['run_dir']}")
