"""The hardware contract a run is judged by, and the one verdict over a run's figures (pure,
stdlib only): ``fleet run`` judges its measured figures with it, ``fleet replay`` a log's, and
``controller.outcome`` prints the limits beside the figures."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class VerdictRules:
    """The hardware contract a run is judged by (Robotarium's "will / will NOT run on hardware"),
    from ground truth: the robot discs never overlap (gap ≥ ``min_robot_gap_m``); no robot enters
    the object deeper than ``max_object_penetration_m`` (contact is allowed, a contact patch of a
    centimetre is the solver's); no robot touches a static obstacle or a wall; an arrested object
    stays put (it moves at most ``max_hold_displacement_m``, any vertex, from the start of the
    hold until transport begins: more is an escape); the object never overlaps an obstacle or
    leaves the room by more than ``object_clearance_slack_m``."""

    min_robot_gap_m: float = 0.0
    max_object_penetration_m: float = 0.01
    max_obstacle_contacts: int = 0
    max_hold_displacement_m: float = 0.05
    object_clearance_slack_m: float = 0.01


RULES = VerdictRules()


def judge(figures: Mapping[str, Any], rules: VerdictRules = RULES) -> list[dict[str, Any]]:
    """The one verdict: what in a run's figures breaks the contract (an empty list: clean).

    ``figures`` holds the keys of ``fleet run --json`` and ``fleet replay --json``:
    ``min_clearance_m`` (None: fewer than two robots or unknown), ``max_object_penetration_m``,
    ``obstacle_contacts`` (robot ids), ``hold_displacement_m`` and ``object_min_clearance_m``
    (None: unknown). Each failure is ``{reason, detail}`` with reason ``collision``,
    ``penetration``, ``obstacle_contact``, ``escaped`` or ``object_collision``.
    """
    out: list[dict[str, Any]] = []

    def fail(reason: str, detail: str) -> None:
        out.append({"reason": reason, "detail": detail})

    gap = figures.get("min_clearance_m")
    if gap is not None and gap < rules.min_robot_gap_m:
        fail("collision", f"robot-robot gap {gap:.4g} m")
    depth = figures.get("max_object_penetration_m")
    if depth is not None and depth > rules.max_object_penetration_m:
        fail("penetration", f"a robot {depth:.4g} m inside the object")
    contacts = list(figures.get("obstacle_contacts") or [])
    if len(contacts) > rules.max_obstacle_contacts:
        fail("obstacle_contact", f"robots {contacts} hit an obstacle or a wall")
    moved = figures.get("hold_displacement_m")
    if moved is not None and moved > rules.max_hold_displacement_m:
        fail("escaped", f"the arrested object moved {moved:.3f} m (truth)")
    clear = figures.get("object_min_clearance_m")
    if clear is not None and clear < -rules.object_clearance_slack_m:
        fail("object_collision", f"the object overlapped an obstacle or a wall by {-clear:.3f} m")
    return out
