"""bench/transport_compare.py's bookkeeping: a run whose lockstep missed ticks stays out of the
statistics (counted), rows are kept as runs end and a killed bench resumes without running
them again, and --retry-invalid runs an invalid run once more."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np

from bench import transport_compare as tc


def row(seed: int, strategy: str, *, success=True, t=30.0, valid=True) -> dict:
    return {
        "scenario": "s",
        "seed": seed,
        "strategy": strategy,
        "success": success,
        "success_paper": success,
        "reason": None if valid else "lockstep_lost",
        "transport_time_s": t if success else None,
        "impulse_ns": 600.0 if success else None,
        "lateral_deviation_rms_m": 0.03 if success else None,
        "missed_ticks": 0 if valid else 3,
        "valid": valid,
    }


def test_an_invalid_run_is_left_out_of_the_statistics_and_counted():
    rows = [row(k, "sa") for k in range(4)] + [row(k, "downhill", t=40.0) for k in range(3)]
    rows.append(row(3, "downhill", success=False, valid=False))
    out = tc.aggregate(rows, ("sa", "downhill"), np.random.default_rng(0))
    assert out["downhill"]["runs"] == 3 and out["downhill"]["success"]["rate"] == 1.0
    assert out["invalid_runs"] == [
        {"scenario": "s", "seed": 3, "strategy": "downhill", "reason": "lockstep_lost",
         "missed_ticks": 3}
    ]  # fmt: skip
    assert out["paired"]["sa_vs_downhill"]["paired_runs"] == 3


def jobs(n: int) -> list[tuple]:
    sc = SimpleNamespace(name="s")
    return [(sc, "sa", seed, "suite") for seed in range(n)]


def test_a_resumed_bench_runs_only_what_its_rows_file_lacks(tmp_path, monkeypatch):
    ran: list[int] = []

    def fake(job):
        ran.append(job[2])
        return row(job[2], job[1], valid=job[2] != 2 or ran.count(2) > 1)

    monkeypatch.setattr(tc, "run_case", fake)
    rows_file = tmp_path / "runs.jsonl"
    rows_file.write_text(json.dumps({**row(0, "sa"), "label": "suite"}) + "\n")
    out = tc.run_all(jobs(4), 1, rows_file)
    assert ran == [1, 2, 3]  # seed 0 read back
    assert [r["seed"] for r in out] == [0, 1, 2, 3]
    assert len(rows_file.read_text().splitlines()) == 4  # each run kept as it ended
    ran.clear()
    again = tc.run_all(jobs(4), 1, rows_file, retry_invalid=True)
    assert ran == [2, 2]  # the invalid run is not read back: run, then once more
    assert all(r["valid"] for r in again)
