"""The ``fleet replay --json`` keys: type and meaning, in the order ``metrics_of`` writes them.
The reference page ``docs/reference/replay-json.md`` is generated from these tables
(``controller/docs.py``); ``tests/replay/test_replay.py`` checks that the replay of each golden
log writes exactly these keys. Extend, never rename: tools outside the repository read them."""

from __future__ import annotations

# key -> (type, meaning); times in s on the log's clock (``t0_s`` says what 0 is)
TOP: dict[str, tuple[str, str]] = {
    "log": ("string", "the file replayed"),
    "complete": ("boolean", "the log was closed cleanly (false: cut by a crash; see `recovered`)"),
    "fleet": ("string", "the fleet's name (`fleet.name`)"),
    "mode": (
        "string",
        "what wrote it: `run/<backend>` (a dry run), `daemon/<mission>` (the "
        "lab) or `record` (`fleet record`)",
    ),  # fmt: skip
    "config_recorded": ("boolean", "the run's config is in the log (`fleet.config` metadata)"),
    "messages": ("integer", "messages read"),
    "undecodable": ("integer", "messages whose payload did not decode (counted, skipped)"),
    "start_s": ("number or null", "the first message's stamp"),
    "duration_s": ("number", "from the first message's stamp to the last"),
    "topics": ("object", "per bus key: `count`, `rate_hz` and `expected_rate_hz`"),
    "scene": ("object", "per Foxglove scene channel (`/scene/...`, `/log`): messages"),
    "ros2": ("object", "per ROS 2 topic a robot's driver recorded (`cdr`): messages"),
    "segments": (
        "array",
        "the log's files (a log rolls over into segments): each `file`, "
        "`complete`, `messages` and its time span",
    ),  # fmt: skip
    "recovered": (
        "object or null",
        "what was read from files cut short by a crash: `files`, "
        "`messages`, `seconds` (null: every file was finished)",
    ),  # fmt: skip
    "time_base": ("string", "`sim` (a dry run's clock) or `wall` (the lab's)"),
    "robots": ("object", "per robot id, the keys of the table below"),
    "object": ("object", "the object's figures, the keys of the table below"),
    "phases": ("array", "the job's phases as entered: `{phase, t}`"),
    "events": ("array", "every plan event (`plan/<kind>`): `{t, kind, phase, data}`"),
    "arrested": ("boolean", "an `arrest` event was logged"),
    "arrest_time_s": ("number or null", "when the object was arrested"),
    "arrival_spread_s": ("number or null", "first to last robot's arrival at its point"),
    "estops": ("array", "every e-stop message logged: `{t, engaged, source}`"),
    "link_lost": ("array", "the robots whose driver reported a lost link"),
    "ground_truth": ("boolean", "the log holds the world's truth (a dry run's)"),
    "min_clearance_m": ("number or null", "the smallest gap between two robots' discs"),
    "min_clearance_t": ("number or null", "when it was smallest"),
    "max_object_penetration_m": (
        "number or null",
        "the deepest a robot's disc went into the object",
    ),  # fmt: skip
    "obstacle_contacts": ("array or null", "the robots whose disc touched an obstacle or wall"),
    "hold_displacement_m": (
        "number or null",
        "how far the object moved while held, before the carry",
    ),  # fmt: skip
    "object_min_clearance_m": (
        "number or null",
        "the object's smallest gap to an obstacle or wall",
    ),  # fmt: skip
    "object_min_clearance_t": ("number or null", "when it was smallest"),
    "verdict": (
        "array or null",
        "the contract's broken rules (`penetration`, `obstacle_contact`, ...; empty: none)",
    ),  # fmt: skip
    "transported": ("boolean", "the object was carried (false: no goal, or never held)"),
    "goal_error_m": ("number", "the object's final distance to its goal (carried only)"),
    "goal_error_deg": ("number", "its final heading error"),
    "transport_time_s": ("number", "from the carry's start to its end"),
    "route_length_m": ("number", "the planned route's length"),
    "object_path_length_m": ("number", "how far the object went"),
    "lateral_deviation_rms_m": ("number", "the object's RMS distance from its route"),
    "max_lateral_deviation_m": ("number", "its largest distance from its route"),
    "rearrangements": ("integer", "re-arrangements of the pushers"),
    "relocations": ("integer", "robots moved to a new contact"),
    "planned_force_mean_n": ("number", "the mean total force the transport plans asked for"),
    "safety_margin_m": (
        "number",
        "`approach.safety_margin`, the limit `min_clearance_m` is judged by",
    ),  # fmt: skip
    "goal_tolerance_m": ("number", "`transport.tolerance`"),
    "goal_tolerance_deg": ("number", "`transport.heading_tolerance_deg`"),
    "t0_s": (
        "number",
        "what the times count from: 0 for a dry run, the first message's epoch for a lab log",
    ),  # fmt: skip
    "phase": ("string or null", "the last phase (`failed` after a failure)"),
    "mission_phase": ("string or null", "the last phase before a failure"),
    "failure": (
        "object or null",
        "`{reason, t, detail}`: the job's failure, else the "
        "contract's first broken rule, else an object not delivered",
    ),  # fmt: skip
    "verdict_line": ("string", "the one line a person reads (`DELIVERED ...`, `FAILED ...`)"),
}

ROBOT: dict[str, tuple[str, str]] = {
    "poses": ("integer", "pose measurements logged"),
    "pose_rate_hz": ("number", "their rate"),
    "commands": ("integer", "commands logged"),
    "command_rate_hz": ("number", "their rate"),
    "max_command_speed": ("number", "the fastest command (m/s)"),
    "path_length_m": ("number", "how far the robot went (truth, else estimate)"),
    "final_pose": ("array or null", "its last pose `[x, y, theta]`"),
    "stale_states": ("integer", "its logged estimates marked stale (no fresh pose)"),
    "estimate_error": ("object or null", "the filter's error against the truth (dry run)"),
    "measurement_error": ("object or null", "the measurements' error against the truth"),
}

OBJECT: dict[str, tuple[str, str]] = {
    "poses": ("integer", "the object's pose measurements logged"),
    "path_length_m": ("number", "how far it went"),
    "final_pose": ("array or null", "its last pose `[x, y, theta]`"),
    "estimate_error": ("object or null", "the object filter's error against the truth"),
}

# written only when the object has a goal (``transport_figures``) ...
GOAL_ONLY = ("transported",)
# ... and only once it was carried
CARRIED_ONLY = (
    "goal_error_m",
    "goal_error_deg",
    "transport_time_s",
    "route_length_m",
    "object_path_length_m",
    "lateral_deviation_rms_m",
    "max_lateral_deviation_m",
    "rearrangements",
    "relocations",
    "planned_force_mean_n",
)
# written only when the log holds the run's config (``limits_of``)
CONFIG_ONLY = ("safety_margin_m", "goal_tolerance_m", "goal_tolerance_deg")
