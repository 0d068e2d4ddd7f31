"""How a lab's end is told (``controller/runtime/lab_outcome.py``): the exit status follows the
verdict, judged from the world's truth, not only what the daemon believed."""

from __future__ import annotations

from types import SimpleNamespace

from controller.runtime import lab_outcome

DELIVERED = {
    "transported": True,
    "goal_error_m": 0.12,
    "goal_error_deg": 1.0,
    "transport_time_s": 90.0,
    "phases": [{"phase": "done", "t": 100.0}],
}


def _lab(tmp_path):
    return SimpleNamespace(
        run_dir=tmp_path, ready_s=10.0, parts=[], failure=None, resumed_at=None,
        stopped_at=None, final_estop=None,
    )  # fmt: skip


def test_a_job_the_daemon_ended_well_but_the_truth_failed_exits_1(tmp_path, monkeypatch):
    """A lab run of the README block: the daemon delivered the crate (exit 0), but two robots
    had touched (gap -10 µm by the world's truth): the verdict said FAILED and the exit 0."""
    judged = {
        **DELIVERED,
        "failure": {"reason": "collision", "t": 107.7, "detail": "robot-robot gap -1e-05 m"},
    }
    monkeypatch.setattr(lab_outcome, "_job_figures", lambda log: judged)
    out = lab_outcome.lab_outcome(_lab(tmp_path), 0, False)
    assert out["verdict"].startswith("FAILED collision")
    assert (out["status"], out["exit"], out["reason"]) == ("failed", 1, "collision")


def test_a_clean_delivery_exits_0_and_a_failed_daemon_1(tmp_path, monkeypatch):
    monkeypatch.setattr(lab_outcome, "_job_figures", lambda log: dict(DELIVERED))
    out = lab_outcome.lab_outcome(_lab(tmp_path), 0, False)
    assert out["verdict"].startswith("DELIVERED") and (out["status"], out["exit"]) == ("ok", 0)
    out = lab_outcome.lab_outcome(_lab(tmp_path), 1, False)
    assert (out["status"], out["exit"]) == ("failed", 1)
