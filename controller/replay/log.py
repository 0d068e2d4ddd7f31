"""Replay of a run's MCAP log: metrics, plots and re-publication on the bus (the I/O edge).

``load_run`` reads a log (a crash-cut one up to the cut; a folder of segments as one run) into
tracks and events; ``metrics_of`` turns them into the ``fleet replay --json`` object with the
pure functions of ``controller.replay.metrics`` and judges them with the run's own verdict code;
``controller.viz.plot_run`` draws PNGs; ``controller.replay.republish`` plays the messages back
on a zenoh bus paced on the log's own time; ``controller.replay.check`` is the regression
replay.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
from collections import Counter, defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from controller import geometry, wire
from controller.config import ConfigError, FleetConfig, InputError, parse_config
from controller.events import (
    ArrestEvent,
    Event,
    RearrangeEvent,
    RouteEvent,
    TransportEvent,
    parse_event,
)
from controller.io.recorder import (
    LogRecord,
    drop_none,
    log_is_complete,
    read_log,
    read_metadata,
    segments,
)
from controller.replay import metrics
from controller.runtime.summary import limits_of

E = TypeVar("E", bound=Event)

log = logging.getLogger(__name__)


@dataclass
class RunLog:
    """What a log holds, sorted into tracks (rows t, x, y, theta) and events."""

    path: Path
    complete: bool
    fleet: str | None = None
    config: FleetConfig | None = None
    mode: str = ""
    topics: Counter = field(default_factory=Counter)
    stamps: dict[str, list[float]] = field(default_factory=lambda: defaultdict(list))
    undecodable: int = 0
    measured: dict[str, list] = field(default_factory=lambda: defaultdict(list))
    estimated: dict[str, list] = field(default_factory=lambda: defaultdict(list))
    truth: dict[str, list] = field(default_factory=lambda: defaultdict(list))
    commands: dict[str, list] = field(default_factory=lambda: defaultdict(list))
    stale: dict[str, int] = field(default_factory=Counter)
    object_measured: list = field(default_factory=list)
    object_estimated: list = field(default_factory=list)
    object_truth: list = field(default_factory=list)
    events: list[dict[str, Any]] = field(default_factory=list)
    robot_events: list[dict[str, Any]] = field(default_factory=list)
    estops: list[dict[str, Any]] = field(default_factory=list)
    scene: Counter = field(default_factory=Counter)  # Foxglove scene channels: messages
    ros2: Counter = field(default_factory=Counter)  # ROS 2 robots' own topics (ros2msg/cdr)
    segments: list[dict[str, Any]] = field(default_factory=list)  # file, complete, messages, s
    time_base: str = "wall"  # "sim": log times are sim time on ``epoch_s`` (dry runs)
    epoch_s: float = 0.0


def load_run(path: str | Path) -> RunLog:
    """Read a log (a file, or a folder of segments) into a :class:`RunLog`. Messages that do
    not decode are counted, not fatal."""
    path = Path(path)
    if not path.is_file() and not (path.is_dir() and segments(path)):
        what = "no MCAP segments in this folder" if path.is_dir() else "no such file"
        raise InputError(f"{path}: {what}")
    try:
        run = _read_run(path)
    except OSError as exc:
        raise InputError(f"{path}: {exc.strerror or exc}") from exc
    if not run.topics and not run.complete:
        raise InputError(f"{path}: not an MCAP log (or empty)")
    return run


def _read_run(path: Path) -> RunLog:
    run = RunLog(path=path, complete=log_is_complete(path))
    records = read_metadata(path)
    clock = records.get("fleet.time", {})
    if clock.get("base") == "sim":
        run.time_base, run.epoch_s = "sim", float(clock.get("epoch_s", 0.0))
    meta = records.get("fleet.config")
    if meta:
        run.mode = meta.get("mode", "")
        try:
            data = drop_none(json.loads(meta["config"]))  # logs before the fix wrote nulls
            run.config = parse_config(data, meta.get("source", ""))
        except (ConfigError, ValueError, KeyError) as exc:
            log.warning("%s: the recorded config does not load: %s", path, exc)
        else:
            run.fleet = run.config.fleet.name
    for seg in segments(path):
        part = {"file": str(seg), "complete": log_is_complete(seg), "messages": 0}
        first = last = None
        for rec in read_log(seg):
            part["messages"] += 1
            first = rec.log_time_ns if first is None else min(first, rec.log_time_ns)
            last = rec.log_time_ns if last is None else max(last, rec.log_time_ns)
            _take(run, rec)
        part["seconds"] = 0.0 if first is None else (last - first) / 1e9
        run.segments.append(part)
    return run


def _take(run: RunLog, rec: LogRecord) -> None:
    """One record of the log into the run."""
    if rec.topic.startswith("/"):  # the Foxglove scene or a ROS 2 topic (never a bus key)
        (run.ros2 if "/msg/" in rec.schema else run.scene)[rec.topic] += 1
        return
    parsed = wire.parse_key(rec.topic, run.fleet)
    if run.fleet is None and parsed is not None:
        run.fleet = parsed.fleet
    run.topics[rec.topic] += 1
    try:
        msg = rec.message()
    except wire.WireError:
        run.undecodable += 1
        return
    if msg is None:
        return
    run.stamps[rec.topic].append(msg.t)
    if parsed is not None:
        _sort(run, parsed, msg)


def _sort(run: RunLog, key: wire.KeyParts, msg: Any) -> None:
    """File one decoded message by its registered topic."""
    rid = key.id
    row = (msg.t, getattr(msg, "x", 0.0), getattr(msg, "y", 0.0), getattr(msg, "theta", 0.0))
    match key.topic.name:
        case "robot_pose":
            run.measured[rid].append(row)
        case "robot_state":
            run.estimated[rid].append(row)
            run.stale[rid] += bool(msg.stale)
        case "robot_cmd":
            run.commands[rid].append((msg.t, msg.vx, msg.vy, msg.wz))
        case "robot_event":
            run.robot_events.append({"t": msg.t, "robot": rid, "kind": msg.kind, "data": msg.data})
        case "object_pose":
            run.object_measured.append(row)
        case "object_state":
            run.object_estimated.append(row)
        case "truth_robot":
            run.truth[rid].append(row)
        case "truth_object":
            run.object_truth.append(row)
        case "plan":
            run.events.append({"t": msg.t, "kind": key.what, "phase": msg.phase, "data": msg.data})
        case "estop":
            run.estops.append({"t": msg.t, "engaged": msg.engaged, "source": msg.source})


EPOCH_LIKE = 1e6  # s: stamps past this are epoch seconds (a lab log), not sim time from 0


def log_t0(run: RunLog) -> float:
    """The instant the run's times count from: 0 for a dry run (sim time, from 0), the first
    message's stamp for a lab log (stamped in epoch seconds on the wall clock)."""
    stamps = [t for ts in run.stamps.values() for t in ts]
    first = min(stamps) if stamps else 0.0
    return 0.0 if run.time_base == "sim" or first < EPOCH_LIKE else first


def _rows_shifted(rows: list, dt: float) -> list:
    return [(r[0] - dt, *r[1:]) for r in rows]


def shifted(run: RunLog, dt: float) -> RunLog:
    """A copy of ``run`` with every time ``dt`` earlier (the plots of a lab log, from its
    start); ``run`` itself is left as read."""
    if not dt:
        return run

    def tracks(d: dict[str, list]) -> dict[str, list]:
        return defaultdict(list, {k: _rows_shifted(v, dt) for k, v in d.items()})

    def timed(items: list[dict[str, Any]]) -> list[dict[str, Any]]:
        return [{**e, "t": e["t"] - dt} for e in items]

    return dataclasses.replace(
        run,
        stamps=defaultdict(list, {k: [t - dt for t in v] for k, v in run.stamps.items()}),
        measured=tracks(run.measured),
        estimated=tracks(run.estimated),
        truth=tracks(run.truth),
        commands=tracks(run.commands),
        object_measured=_rows_shifted(run.object_measured, dt),
        object_estimated=_rows_shifted(run.object_estimated, dt),
        object_truth=_rows_shifted(run.object_truth, dt),
        events=timed(run.events),
        robot_events=timed(run.robot_events),
        estops=timed(run.estops),
    )


def phases_of(run: RunLog) -> list[dict[str, Any]]:
    """The phases the run went through, each with the time it began (from the plan events)."""
    phases: list[dict[str, Any]] = []
    for e in sorted(run.events, key=lambda e: e["t"]):
        if e["phase"] and (not phases or phases[-1]["phase"] != e["phase"]):
            phases.append({"phase": e["phase"], "t": e["t"]})
    return phases


def events_of(run: RunLog, kind: str) -> list[dict[str, Any]]:
    """The run's plan events of one kind (capture, route, transport, ...), in time order."""
    return sorted((e for e in run.events if e["kind"] == kind), key=lambda e: e["t"])


def typed_events(run: RunLog, cls: type[E]) -> list[tuple[float, E]]:
    """The run's plan events of one typed kind with their message stamps, in time order (an
    event of that kind whose fields do not fit is left out: ``run.events`` keeps it raw)."""
    out = []
    for e in events_of(run, cls.KIND):
        ev = parse_event(e["kind"], e["data"])
        if isinstance(ev, cls):
            out.append((e["t"], ev))
    return out


def track(rows: list) -> metrics.Track:
    """A track from logged rows (t, x, y, theta)."""
    return metrics.Track.from_rows(rows)


def _topic_figures(run: RunLog, key: str, count: int) -> dict[str, Any]:
    """Count and rate of one key, with the registry's expected rate (None for events)."""
    rate = round(metrics.rate_hz(sorted(run.stamps.get(key, []))), 3)
    parsed = wire.parse_key(key, run.fleet)
    expected = parsed.topic.rate_hz if parsed is not None and parsed.topic.rate_hz > 0 else None
    return {"count": count, "rate_hz": rate, "expected_rate_hz": expected}


def _track(rows: list) -> metrics.Track:
    return metrics.Track.from_rows(rows)


def metrics_of(run: RunLog) -> dict[str, Any]:
    """The ``fleet replay --json`` object."""
    cfg = run.config
    ids = list(cfg.robot_ids) if cfg else sorted(set(run.measured) | set(run.truth))
    all_t = [t for ts in run.stamps.values() for t in ts]
    robots: dict[str, Any] = {}
    for rid in ids:
        meas = _track(run.measured.get(rid, []))
        est = _track(run.estimated.get(rid, []))
        truth = _track(run.truth.get(rid, []))
        cmd = np.asarray(run.commands.get(rid, []), dtype=float).reshape(-1, 4)
        best = truth if len(truth) else (est if len(est) else meas)
        robots[rid] = {
            "poses": len(meas),
            "pose_rate_hz": metrics.rate_hz(meas.t),
            "commands": len(cmd),
            "command_rate_hz": metrics.rate_hz(cmd[:, 0]),
            "max_command_speed": float(np.max(np.hypot(cmd[:, 1], cmd[:, 2]))) if len(cmd) else 0,
            "path_length_m": metrics.path_length(best.pose[:, :2]),
            "final_pose": best.pose[-1].tolist() if len(best) else None,
            "stale_states": int(run.stale.get(rid, 0)),
            "estimate_error": metrics.tracking_error(est, truth),
            "measurement_error": metrics.tracking_error(meas, truth),
        }
    otruth = _track(run.object_truth)
    oest = _track(run.object_estimated)
    omeas = _track(run.object_measured)
    obest = otruth if len(otruth) else (oest if len(oest) else omeas)
    arrests = typed_events(run, ArrestEvent)
    phases = phases_of(run)
    out: dict[str, Any] = {
        "log": str(run.path),
        "complete": run.complete,
        "fleet": run.fleet,
        "mode": run.mode,
        "config_recorded": cfg is not None,
        "messages": int(sum(run.topics.values())),
        "undecodable": run.undecodable,
        "start_s": min(all_t) if all_t else None,
        "duration_s": (max(all_t) - min(all_t)) if all_t else 0.0,
        "topics": {k: _topic_figures(run, k, n) for k, n in sorted(run.topics.items())},
        "scene": dict(sorted(run.scene.items())),
        "ros2": dict(sorted(run.ros2.items())),
        "segments": run.segments,
        "recovered": _recovered(run.segments),
        "time_base": run.time_base,
        "robots": robots,
        "object": {
            "poses": len(omeas),
            "path_length_m": metrics.path_length(obest.pose[:, :2]),
            "final_pose": obest.pose[-1].tolist() if len(obest) else None,
            "estimate_error": metrics.tracking_error(oest, otruth),
        },
        "phases": phases,
        "events": run.events,
        "arrested": bool(events_of(run, "arrest")),
        "arrest_time_s": arrests[0][0] if arrests else None,
        "arrival_spread_s": arrests[0][1].arrival_spread_s if arrests else None,
        "estops": run.estops,
        "link_lost": sorted({e["robot"] for e in run.robot_events if e["kind"] == "link_lost"}),
        "ground_truth": bool(run.truth),
        "min_clearance_m": None,
        "min_clearance_t": None,
        "max_object_penetration_m": None,
        "obstacle_contacts": None,
        "hold_displacement_m": None,
        "object_min_clearance_m": None,
        "object_min_clearance_t": None,
        "verdict": None,
    }
    if cfg is not None:
        # discs from ground truth when the log has it (dry run), else from the estimates
        src = run.truth if run.truth else run.estimated
        tracks = [_track(src.get(rid, [])) for rid in ids]
        radii = [cfg.robot(rid).radius for rid in ids]
        have = [i for i, tr in enumerate(tracks) if len(tr)]
        tr_h, r_h = [tracks[i] for i in have], [radii[i] for i in have]
        mc = metrics.min_clearance(tr_h, r_h)
        if mc is not None:
            out["min_clearance_m"], out["min_clearance_t"] = mc
        obj = otruth if run.truth else oest
        if len(obj) and tr_h:
            poly = geometry.ensure_ccw(cfg.object_polygon())
            depth, _ = metrics.object_penetration(tr_h, r_h, obj, poly)
            out["max_object_penetration_m"] = depth
        hits = metrics.obstacle_contacts(tr_h, r_h, cfg.obstacle_polygons(), cfg.bounds_array())
        out["obstacle_contacts"] = sorted(ids[have[i]] for i in hits)
        out.update(_object_figures(cfg, obj, phases))
        out.update(transport_figures(run, cfg, obj, phases))
        from controller.verdict import judge  # the run's own verdict code

        out["verdict"] = judge(out)
        out.update(limits_of(cfg))
    out.update(_outcome(run, out))
    return out


def _outcome(run: RunLog, out: dict[str, Any]) -> dict[str, Any]:
    """The run's end as the log tells it: ``t0_s`` (what its times count from: 0 for a dry
    run, the first message's epoch for a lab log), ``phase`` (the last; ``failed`` after a
    failure) and ``mission_phase`` (the last before a failure), ``failure`` ({reason, t,
    detail}: the mission's ``failure`` event, else the contract's first broken rule, else an
    object not delivered) and ``verdict_line`` (``controller.outcome``)."""
    from controller.outcome import verdict_line

    phases = out["phases"]
    words = [p["phase"] for p in phases]
    result = {
        "t0_s": log_t0(run),
        "phase": words[-1] if words else None,
        "mission_phase": next((w for w in reversed(words) if w != "failed"), None),
        "failure": _failure(run, out),
    }
    result["verdict_line"] = verdict_line({**out, **result})
    return result


def _failure(run: RunLog, out: dict[str, Any]) -> dict[str, Any] | None:
    for e in events_of(run, "failure"):
        data = e["data"] if isinstance(e["data"], dict) else {}
        t = data.get("t")
        return {
            "reason": str(data.get("reason") or "failed"),
            "t": t if isinstance(t, int | float) else e["t"],
            "detail": str(data.get("detail") or ""),
        }
    when = {"collision": "min_clearance_t", "object_collision": "object_min_clearance_t"}
    for f in out.get("verdict") or []:
        return {"reason": f["reason"], "t": out.get(when.get(f["reason"], "")), **f}
    if out.get("transported") is False and out["phases"] and out["phases"][-1]["phase"] == "done":
        detail = (
            f"the object ended {out.get('goal_error_m', math.nan):.2f} m and "
            f"{out.get('goal_error_deg', math.nan):.1f} deg from object.goal"
        )
        return {"reason": "not_delivered", "t": out["phases"][-1]["t"], "detail": detail}
    return None


CARRIED = ("route", "rearrange", "transport")  # the phases after which the object is carried


def _object_figures(cfg: FleetConfig, obj: metrics.Track, phases: list[dict]) -> dict:
    """The object's figures of the verdict, as the run scores them: how far the arrested object
    moved from the start of the (last) hold until it was carried (``hold_displacement_m``), and
    its smallest clearance to obstacles and walls (``object_min_clearance_m``)."""
    poly = geometry.ensure_ccw(cfg.object_polygon())
    carried = next((p["t"] for p in phases if p["phase"] in CARRIED), math.inf)
    holds = [p["t"] for p in phases if p["phase"] == "hold" and p["t"] < carried]
    end = min(carried, float(obj.t[-1])) if len(obj) else carried
    moved = metrics.hold_displacement(obj, poly, holds[-1], end) if holds else None
    bounds = cfg.bounds_array() if cfg.world.walls else None
    clear = metrics.object_clearance(obj, poly, cfg.obstacle_polygons(), bounds)
    return {
        "hold_displacement_m": moved,
        "object_min_clearance_m": None if clear is None else clear[0],
        "object_min_clearance_t": None if clear is None else clear[1],
    }


def transport_figures(
    run: RunLog, cfg: FleetConfig, obj: metrics.Track, phases: list[dict]
) -> dict[str, Any]:
    """The transport as ``fleet run --json`` reports it, from the log: delivery and the error
    at the goal (from the object's truth when logged, else its estimate), transport time, the
    route's length and the object's path, its lateral deviation from the route, re-arrangements
    and relocations. The true contact forces are the world's and are not logged: the planned
    ones (``planned_force_mean_n``, from ``plan/transport``) stand in. Empty without a goal."""
    goal = cfg.object.goal
    start = next((p["t"] for p in phases if p["phase"] in CARRIED), None)
    if goal is None:
        return {}
    if start is None or not len(obj):
        return {"transported": False}
    ends = [p["t"] for p in phases if p["t"] > start and p["phase"] in ("done", "failed")]
    end = ends[0] if ends else None
    routes = [ev for _, ev in typed_events(run, RouteEvent)]
    keep = obj.t >= start
    if end is not None:
        keep &= obj.t <= end
    pose = obj.pose[-1]
    err = float(np.linalg.norm(pose[:2] - np.asarray(goal[:2])))
    err_deg = float(np.degrees(abs(geometry.wrap_angle(pose[2] - goal[2]))))
    t = cfg.transport
    delivered = bool(events_of(run, "delivered"))
    within = err <= t.tolerance and err_deg <= t.heading_tolerance_deg
    poly = geometry.ensure_ccw(cfg.object_polygon())
    centre = geometry.centroid(poly)
    path = np.array([geometry.transform(centre[None], p)[0] for p in obj.pose[keep]])
    lat = np.zeros(0)
    if routes and keep.any():
        wp = np.asarray(routes[0].waypoints, float).reshape(-1, 3)[:, :2]
        if len(wp) > 1:
            lat = metrics.lateral_deviation(obj.pose[keep, :2], wp)
    plans = typed_events(run, TransportEvent)
    planned = [f for _, e in plans for f in (e.forces or [[]])[0] or [] if f]
    return {
        "transported": delivered and within,
        "goal_error_m": err,
        "goal_error_deg": err_deg,
        "transport_time_s": None if end is None else round(end - start, 3),
        "route_length_m": routes[0].length_m if routes else None,
        "object_path_length_m": metrics.path_length(path) if len(path) else 0.0,
        "lateral_deviation_rms_m": float(np.sqrt(np.mean(lat**2))) if len(lat) else None,
        "max_lateral_deviation_m": float(lat.max()) if len(lat) else None,
        "rearrangements": len(events_of(run, "rearrange")),
        "relocations": _relocations(run),
        "planned_force_mean_n": float(np.mean(planned)) if planned else None,
    }


def _relocations(run: RunLog) -> int:
    """Robots sent to a new contact: the movers of every re-arrangement, and each robot that
    starts relocating during the transport (it appears in a local plan's ``relocating``)."""
    n = sum(len(e.moving) for _, e in typed_events(run, RearrangeEvent))
    before: set[str] = set()
    for _, e in typed_events(run, TransportEvent):
        now = set(e.relocating)
        n += len(now - before)
        before = now
    return n


def _recovered(parts: list[dict[str, Any]]) -> dict[str, Any] | None:
    """What was read from files cut short by a crash (None: every file was finished)."""
    cut = [p for p in parts if not p["complete"]]
    if not cut:
        return None
    return {
        "files": [p["file"] for p in cut],
        "messages": sum(p["messages"] for p in cut),
        "seconds": round(sum(p["seconds"] for p in cut), 3),
    }


def print_summary(r: dict) -> None:
    """The ``fleet replay`` summary as text on stdout: the log, each robot, the object, then
    the outcome (``controller.outcome``: the verdict line, the figures with units and limits,
    times from the run's start) and the plots or the next steps."""
    from controller.outcome import metres, next_steps, outcome_table, verdict_line

    print(f"{r['log']}: {'complete' if r['complete'] else 'cut short (crash?)'}, {r['mode']}")
    if len(r.get("segments", [])) > 1:
        print(f"  {len(r['segments'])} segments")
    if r.get("recovered"):
        rec = r["recovered"]
        print(
            f"  recovered from cut files: {rec['messages']} messages, {rec['seconds']:.2f} s "
            f"({', '.join(rec['files'])})"
        )
    print(
        f"  {r['messages']} messages over {r['duration_s']:.1f} s, {r['undecodable']} undecodable"
    )
    for rid, m in r["robots"].items():
        err = m["estimate_error"]
        e = f", estimate RMSE {err['rmse_m'] * 100:.1f} cm" if err else ""
        print(
            f"  {rid}: {m['poses']} poses ({m['pose_rate_hz']:.1f} Hz), {m['commands']} commands "
            f"({m['command_rate_hz']:.1f} Hz), path {m['path_length_m']:.2f} m{e}"
        )
    o = r["object"]
    final = o["final_pose"]
    at = f", final x {final[0]:.3f} m, y {final[1]:.3f} m, θ {final[2]:.3f} rad" if final else ""
    print(f"  object: path {metres(o['path_length_m'])}{at}")
    if r.get("link_lost"):
        print(f"  link lost: {', '.join(r['link_lost'])}")
    if r.get("estops"):
        print(f"  e-stops: {len(r['estops'])} (engaged or released on the bus)")
    print(verdict_line(r))
    table = outcome_table(r)
    if table:
        print(table)
    if r.get("plots"):
        for p in r["plots"]:
            print(f"  plot: {p}")
    else:
        print("next:")
        for step in next_steps(r, r["log"]):
            print(f"  {step}")
