"""A run's outcome in words (pure: strings from a dict, no I/O): one verdict line, a table of
the figures with their units and the limits beside the safety ones, and what to do next.

Every function takes the ``--json``-shaped dict of ``fleet run``, of ``fleet replay`` or the one
``fleet daemon`` builds at its end; any key may be missing. Times that are instants (a failure's
``t``, ``arrest_time_s``, the phases' ``t``, ``min_clearance_t``) are shown relative to
``t0_s`` when the dict has it (a lab log is stamped in epoch seconds: ``t0_s`` is its start), as
they are otherwise (the dry run's sim time starts at 0).

Verdicts: ``DELIVERED``, ``ARRESTED`` (no goal set), ``DONE`` (a bring-up mission), ``FAILED
<reason>`` (with the failure's detail, one line), ``STOPPED (<why>)`` (interrupted, the log
ends, ...)."""

from __future__ import annotations

import math
import shlex
from collections.abc import Callable, Mapping
from pathlib import PurePath
from typing import Any

from controller.verdict import RULES

Summary = Mapping[str, Any]

DETAIL_CHARS = 160  # the failure's detail in the verdict line (the table has all of it)
LABEL = 34  # the table's first column


# --------------------------------------------------------------------------- numbers


def sig(x: float, digits: int = 3) -> str:
    """``x`` with ``digits`` significant digits, never in exponent form, trailing zeros
    dropped: 0.0420 → ``0.042``, 109.3 → ``109``, 16.05 → ``16.1``."""
    if not math.isfinite(x):
        return str(x)
    if x == 0:
        return "0"
    decimals = max(digits - 1 - math.floor(math.log10(abs(x))), 0)
    text = f"{x:.{decimals}f}"
    if "." in text:
        text = text.rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def metres(x: float) -> str:
    """A length: under a centimetre in mm (``5.5 mm``), else in m (``0.042 m``)."""
    if x != 0 and abs(x) < 0.01:
        return f"{sig(x * 1e3, 2)} mm"
    return f"{sig(x, 3)} m"


def seconds(x: float) -> str:
    """A duration: ``0.75 s``, ``35.9 s``, ``109 s``."""
    return f"{sig(x, 3)} s"


def instant(x: float) -> str:
    """A moment of the run (s since its start), to a tenth: ``16.1 s``, ``40.0 s``."""
    return f"{x:.1f} s"


def degrees(x: float) -> str:
    return f"{x:.1f}°"


def newtons(x: float) -> str:
    return f"{sig(x, 3)} N"


def impulse(x: float) -> str:
    return f"{sig(x, 3)} N·s"


def _num(x: Any) -> float | None:
    """A finite number, or None (missing, None, a bool, not a number)."""
    if isinstance(x, bool) or not isinstance(x, int | float):
        return None
    return float(x) if math.isfinite(x) else None


def _t0(s: Summary) -> float:
    return _num(s.get("t0_s")) or 0.0


def _at(s: Summary, t: Any) -> float | None:
    """An instant of the run relative to its start (``t0_s``)."""
    v = _num(t)
    return None if v is None else v - _t0(s)


def one_line(text: str, limit: int = DETAIL_CHARS) -> str:
    """``text`` on one line (whitespace collapsed), cut at ``limit`` characters with ``…``."""
    flat = " ".join(str(text).split())
    return flat if len(flat) <= limit else flat[: limit - 1].rstrip() + "…"


# --------------------------------------------------------------------------- the verdict


def failure_of(s: Summary) -> dict[str, Any] | None:
    """The run's failure ``{reason, t, detail}``: its ``failure`` field, else its ``reason``
    alone; None for a run that did not fail."""
    f = s.get("failure")
    if isinstance(f, Mapping) and f.get("reason"):
        return {"reason": str(f["reason"]), "t": f.get("t"), "detail": f.get("detail") or ""}
    if s.get("reason"):
        return {"reason": str(s["reason"]), "t": None, "detail": ""}
    if s.get("status") == "failed":
        return {"reason": "failed", "t": None, "detail": ""}
    return None


def _end(s: Summary) -> float | None:
    """When the run (or the log) ended, relative to its start."""
    if _num(s.get("sim_time_s")) is not None:
        return float(s["sim_time_s"])
    start, span = _num(s.get("start_s")), _num(s.get("duration_s"))
    if span is not None:
        return span + ((start - _t0(s)) if start is not None else 0.0)
    return None


def _last_phase(s: Summary) -> str | None:
    phases = s.get("phases") or []
    last = phases[-1].get("phase") if phases and isinstance(phases[-1], Mapping) else None
    phase = s.get("mission_phase") if s.get("phase") == "failed" else s.get("phase")
    return str(phase or last) if (phase or last) else None


def _tail(s: Summary) -> str:
    """How long it ran: ``109 s of sim time in 64 s``, ``35.9 s of log``, ``40 s``."""
    sim, wall = _num(s.get("sim_time_s")), _num(s.get("wall_time_s"))
    if sim is not None:
        return f"{seconds(sim)} of sim time" + (f" in {seconds(wall)}" if wall is not None else "")
    span = _num(s.get("duration_s"))
    if span is None:
        return ""
    what = "of log" if "complete" in s else "on the wall clock"
    cut = ", the log cut short" if s.get("complete") is False else ""
    return f"{seconds(span)} {what}{cut}"


def _head(s: Summary) -> str:
    """The verdict's first words."""
    fail = failure_of(s)
    if fail is not None:
        t = _at(s, fail["t"])
        words = f"FAILED {fail['reason']}" + (f" at {instant(t)}" if t is not None else "")
        return words + (f": {one_line(fail['detail'])}" if fail["detail"] else "")
    phase = _last_phase(s)
    stopped = s.get("stopped")
    transported = s.get("transported")
    if not stopped and transported is True:
        err, deg = _num(s.get("goal_error_m")), _num(s.get("goal_error_deg"))
        where = " / ".join(
            w for w in (err is not None and metres(err), deg is not None and degrees(deg)) if w
        )
        took = _num(s.get("transport_time_s"))
        return (
            "DELIVERED"
            + (f" {where} from the goal" if where else "")
            + (f" after {seconds(took)} of transport" if took is not None else "")
        )
    if not stopped and phase == "done" and s.get("arrested") and transported is None:
        t = _at(s, s.get("arrest_time_s"))
        return "ARRESTED" + (f" at {instant(t)}" if t is not None else "") + " (no goal set)"
    if not stopped and phase == "done":
        return "DONE (the mission's end)"
    why = stopped or ("the log ends" if "complete" in s else "unfinished")
    end = _end(s)
    return (
        f"STOPPED ({why})"
        + (f" in phase {phase}" if phase else "")
        + (f" at {instant(end)}" if end is not None else "")
    )


def verdict_line(summary: Summary) -> str:
    """One line: what became of the job, when, and how long the run took."""
    tail = _tail(summary)
    return _head(summary) + (f"; {tail}" if tail else "")


# --------------------------------------------------------------------------- the table


def _robots(values: Any, unit: Callable[[float], str]) -> str | None:
    """A per-robot dict as ``r1 5.5 mm, r2 4.7 mm`` (None: not a dict)."""
    if not isinstance(values, Mapping) or not values:
        return None
    parts = [
        f"{k} {unit(v)}" for k, v in sorted(values.items(), key=_natural) if _num(v) is not None
    ]
    return ", ".join(parts) or None


def _natural(item: tuple[Any, Any]) -> tuple[str, int]:
    """r2 before r10."""
    key = str(item[0])
    digits = key.lstrip("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ_-")
    return (key[: len(key) - len(digits)], int(digits) if digits.isdigit() else -1)


def _flag(ok: bool, bad: str) -> str:
    return "ok" if ok else bad


def _clearance(s: Summary, v: float) -> str:
    margin = _num(s.get("safety_margin_m"))
    if v < RULES.min_robot_gap_m:
        return f"{metres(v)} (robots overlap: COLLISION)"
    if margin is None:
        return metres(v)
    return f"{metres(v)} (margin {metres(margin)}: {_flag(v >= margin, 'UNDER')})"


def _object_clearance(s: Summary, v: float) -> str:
    slack = RULES.object_clearance_slack_m
    return f"{metres(v)} (overlap allowed {metres(slack)}: {_flag(v >= -slack, 'OVERLAPS')})"


def _limit(v: float, limit: float, word: str, unit: Callable[[float], str] = metres) -> str:
    return f"{unit(v)} (limit {unit(limit)}: {_flag(v <= limit, word)})"


def _tolerance(v: float, tol: float | None, unit: Callable[[float], str]) -> str:
    if tol is None:
        return unit(v)
    return f"{unit(v)} (tolerance {unit(tol)}: {_flag(v <= tol, 'OUTSIDE')})"


def _phases(s: Summary) -> str | None:
    rows = [p for p in s.get("phases") or [] if isinstance(p, Mapping) and "phase" in p]
    if not rows:
        return None
    return " → ".join(
        f"{p['phase']} {instant(t)}" if (t := _at(s, p.get("t"))) is not None else str(p["phase"])
        for p in rows
    )


def _latency(values: Any) -> str | None:
    if not isinstance(values, Mapping):
        return None
    parts = [
        f"{k} p99 {seconds(v['p99'])}" + (f" ({v['late']} late)" if _num(v.get("late")) else "")
        for k, v in values.items()
        if isinstance(v, Mapping) and _num(v.get("p99")) is not None
    ]
    return ", ".join(parts) or None


def _failure_row(s: Summary) -> str | None:
    fail = failure_of(s)
    if fail is None:
        return None
    t = _at(s, fail["t"])
    return (
        fail["reason"]
        + (f" at {instant(t)}" if t is not None else "")
        + (f": {one_line(fail['detail'], 400)}" if fail["detail"] else "")
    )


def _contract(v: Any) -> str | None:
    if not isinstance(v, list):
        return None
    reasons = [str(f.get("reason")) for f in v if isinstance(f, Mapping)]
    return "clean" if not reasons else "BROKEN: " + ", ".join(reasons)


def _contacts(v: Any) -> str | None:
    if not isinstance(v, list):
        return None
    return "none" if not v else "HIT by " + ", ".join(map(str, v))


def _count(v: Any) -> str | None:
    n = _num(v)
    return None if n is None else str(int(n))


def _yes(v: Any) -> str | None:
    return None if v is None else ("yes" if v else "no")


def _plain(unit: Callable[[float], str]) -> Callable[[Summary, Any], str | None]:
    return lambda s, v: None if _num(v) is None else unit(float(v))


def _when(s: Summary, v: Any) -> str | None:
    t = _at(s, v)
    return None if t is None else instant(t)


def _with(fn: Callable[[Summary, float], str]) -> Callable[[Summary, Any], str | None]:
    return lambda s, v: None if _num(v) is None else fn(s, float(v))


def _of(fn: Callable[[Any], str | None]) -> Callable[[Summary, Any], str | None]:
    return lambda s, v: fn(v)


Row = tuple[str, Callable[[Summary, Any], str | None]]

SECTIONS: tuple[tuple[str, tuple[Row, ...]], ...] = (
    (
        "outcome",
        (
            ("status", _of(lambda v: None if v is None else str(v))),
            ("failure", lambda s, v: _failure_row(s)),
            ("phases", lambda s, v: _phases(s)),
        ),
    ),
    (
        "capture",
        (
            ("arrested", _of(_yes)),
            ("arrest_time_s", _when),
            ("arrival_spread_s", _plain(seconds)),
            (
                "hold_displacement_m",
                _with(lambda s, v: _limit(v, RULES.max_hold_displacement_m, "ESCAPED")),
            ),
            ("contact_gaps_at_arrest_m", _of(lambda v: _robots(v, metres))),
            ("object_gave_up_at_s", _when),
        ),
    ),
    (
        "transport",
        (
            ("transported", _of(_yes)),
            (
                "goal_error_m",
                _with(lambda s, v: _tolerance(v, _num(s.get("goal_tolerance_m")), metres)),
            ),
            (
                "goal_error_deg",
                _with(lambda s, v: _tolerance(v, _num(s.get("goal_tolerance_deg")), degrees)),
            ),
            ("transport_time_s", _plain(seconds)),
            ("route_length_m", _plain(metres)),
            ("object_path_length_m", _plain(metres)),
            ("lateral_deviation_rms_m", _plain(metres)),
            ("max_lateral_deviation_m", _plain(metres)),
            ("contact_force_mean_n", _plain(newtons)),
            ("contact_force_max_n", _plain(newtons)),
            ("contact_impulse_ns", _plain(impulse)),
            ("planned_force_mean_n", _plain(newtons)),
            ("transport_object_min_clearance_m", _plain(metres)),
            ("rearrangements", _of(_count)),
            ("relocations", _of(_count)),
        ),
    ),
    (
        "safety",
        (
            ("min_clearance_m", _with(_clearance)),
            ("min_clearance_t", _when),
            (
                "max_object_penetration_m",
                _with(lambda s, v: _limit(v, RULES.max_object_penetration_m, "OVER")),
            ),
            ("obstacle_contacts", _of(_contacts)),
            (
                "object_min_clearance_m",
                _with(_object_clearance),
            ),
            ("verdict", _of(_contract)),
        ),
    ),
    (
        "run",
        (
            ("sim_time_s", _plain(seconds)),
            ("wall_time_s", _plain(seconds)),
            ("duration_s", _plain(seconds)),
            ("missed_ticks", _of(_count)),
            ("watchdog_stops", _of(_count)),
            ("plan_latency_s", _of(_latency)),
            ("log", _of(lambda v: None if not v else str(v))),
        ),
    ),
)


def outcome_table(summary: Summary) -> str:
    """The figures a person reads after a run, by section, each under its ``--json`` name,
    rounded, with its unit, and the limit beside the safety figures (``UNDER``, ``OVER``, ...
    when broken). Missing figures are left out."""
    lines: list[str] = []
    for title, rows in SECTIONS:
        got = [(k, fn(summary, summary.get(k))) for k, fn in rows]
        got = [(k, v) for k, v in got if v is not None]
        if got:
            lines.append(f"{title}:")
            lines += [f"  {k:<{LABEL}}{v}" for k, v in got]
    return "\n".join(lines)


# --------------------------------------------------------------------------- next steps

HINTS = {
    "no_route": "the route alone: fleet plan route --config {config} --plot route.png",
    "pinned": "the capture set alone: fleet plan capture --config {config} --plot capture.png",
    "no_capture": "the capture set alone: fleet plan capture --config {config} --plot capture.png",
    "too_heavy": "the capture set alone: fleet plan capture --config {config} --plot capture.png",
    "lockstep_lost": "the machine was too busy for the lockstep: run it again on a quieter one",
}


def next_steps(summary: Summary, log_path: str | None) -> list[str]:
    """What to run next: the plots of the log, the Foxglove layout to open it with, and for
    some failures the planner that refused, alone; a safety figure under its margin named."""
    steps: list[str] = []
    log = log_path or summary.get("log")
    if log:
        p = PurePath(str(log))
        plots = p.with_name(p.stem + "-plots") if p.suffix else p.with_name(p.name + "-plots")
        steps.append(f"plots: fleet replay {shlex.quote(str(p))} --plots {shlex.quote(str(plots))}")
        steps.append(
            f"Foxglove: open {shlex.quote(str(p))} with the layout "
            "`fleet log layout --out fleet-layout.json` writes"
        )
    else:
        steps.append("Foxglove: the layout for a log: fleet log layout --out fleet-layout.json")
    fail = failure_of(summary)
    hint = HINTS.get(fail["reason"]) if fail else None
    if hint:
        steps.append(hint.format(config=shlex.quote(str(summary.get("config") or "F"))))
    gap, margin = _num(summary.get("min_clearance_m")), _num(summary.get("safety_margin_m"))
    if gap is not None and margin is not None and gap < margin:
        when = _at(summary, summary.get("min_clearance_t"))
        steps.append(
            f"robots came within {metres(gap)} of each other, under approach.safety_margin "
            f"{metres(margin)}"
            + (f" (at {instant(when)})" if when is not None else "")
            + ": see clearance.png in the plots"
        )
    return steps


def report(summary: Summary, log_path: str | None = None) -> str:
    """The three together, as ``fleet run`` (text), ``fleet daemon`` and ``fleet replay`` end:
    the verdict line, the table, ``next:`` and the steps."""
    steps = next_steps(summary, log_path)
    table = outcome_table(summary)
    return "\n".join(
        [verdict_line(summary), *([table] if table else []), "next:", *(f"  {s}" for s in steps)]
    )
