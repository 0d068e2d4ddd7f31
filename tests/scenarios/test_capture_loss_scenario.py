"""Robot loss mid-approach, end to end (issue 17): one assigned robot's link fails a few
seconds into the approach (its sim driver fails as a real link does: no poses, commands
refused; its agent stops it, reports ``link_lost`` and drops its liveliness token); the
controller takes it for lost, re-plans the capture over the robots left, and they still
arrest the object, in the ``ideal`` world over zenoh."""

from __future__ import annotations

from controller.mission.factory import build_mission
from controller.mission.summary import JobSummary
from controller.runtime import dry_run
from controller.runtime.dry_run import DryRun, judge
from tests.support.capture_scenarios import SCENARIOS, scenario

CUT_AFTER = 3.0  # s into the approach


class CutLink:
    """The job, with one assigned robot's link failing ``CUT_AFTER`` s into the approach (the
    test's hand on the robot side: the mission itself only sees the bus)."""

    def __init__(self, job, drivers: list) -> None:
        self.job, self.drivers = job, drivers
        self.approach_t: float | None = None
        self.cut: tuple[str, float] | None = None
        self.replanned_t: float | None = None

    def plan(self, view):
        intent = self.job.plan(view)
        if intent.report.phase == "approach" and self.approach_t is None:
            self.approach_t = view.t
        if self.cut is None and self.approach_t is not None:
            if view.t - self.approach_t >= CUT_AFTER:
                i = int(self.job.assignment[0])
                self.drivers[i].fail_link("test: link cut mid-approach")
                self.cut = (view.ids[i], view.t)
        if self.cut is not None and self.replanned_t is None:
            if any(e.kind == "robot_lost" for e in intent.report.events):
                self.replanned_t = view.t
        return intent

    def safety(self, view, intent):
        return self.job.safety(view, intent)

    def summary(self) -> JobSummary:
        return self.job.summary()


def test_an_assigned_robot_cut_mid_approach_the_rest_arrest_the_object(tmp_path, monkeypatch):
    poly, motion, kinds, start, obstacles = SCENARIOS["L-sine-default"]
    cfg = scenario(poly, motion, kinds, start, obstacles, seed=2)
    drivers: list = []
    make = dry_run.make_sim_drivers

    def keep(cfg_, hub):
        out, emulators = make(cfg_, hub)
        drivers.extend(out)
        return out, emulators

    monkeypatch.setattr(dry_run, "make_sim_drivers", keep)
    mission = CutLink(build_mission(cfg), drivers)
    res = DryRun(cfg, mission, tmp_path / "run.mcap", max_time=150).run()
    assert mission.cut is not None and mission.replanned_t is not None
    lost, cut_t = mission.cut
    print(
        f"cut {lost} at {cut_t:.2f} s, lost and re-planned at {mission.replanned_t:.2f} s, "
        f"arrest at {res['arrest_time_s']} s, {len(res['mission']['assigned'])} robots"
    )
    assert res["mission"]["robots_lost"] == [lost] and res["mission"]["loss_replans"] == 1
    assert lost not in res["mission"]["assigned"]
    assert res["arrested"] and res["done"] and not res["failed"], res
    assert judge(res) == []
    assert lost not in res["contact_gaps_at_arrest_m"]
