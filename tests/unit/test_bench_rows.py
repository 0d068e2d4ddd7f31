"""The transport comparisons' tables rebuild from their committed runs (issue 34 item 4): every
run of a ``transport_compare`` row is in the row's JSON-lines file under ``bench/results/``,
and aggregating those runs again gives the row's figures (the results pages are rendered from
the rows: ``test_docs`` checks that). Bootstrap intervals depend on the order the generator is
drawn in, so the check is on what does not: counts, rates and Wilson intervals, medians and n,
McNemar's and Wilcoxon's tests and Holm's adjustment."""

from __future__ import annotations

import json
import shlex
from pathlib import Path

import numpy as np
import pytest

from bench.transport_compare import STRATEGIES, aggregate

ROOT = Path(__file__).resolve().parents[2]
ROWS = sorted(
    p
    for p in (ROOT / "bench" / "rows").glob("*.json")
    if json.loads(p.read_text())["bench"] == "transport_compare"
)


#: a row's sets of runs and the label their runs carry in the JSON-lines file
SETS = (("closed_loop", "suite"), ("robustness", "sweep"), ("varied", "varied"))


def _args(command: str) -> dict[str, str]:
    words = shlex.split(command)
    return {w: words[i + 1] for i, w in enumerate(words[:-1]) if w.startswith("--")}


def _strip(agg: dict) -> dict:
    """The order-free figures of an aggregate: bootstrap intervals dropped."""
    out: dict = {}
    for key, value in agg.items():
        if isinstance(value, dict):
            out[key] = _strip({k: v for k, v in value.items() if k != "ci95" or "k" in value})
        else:
            out[key] = value
    return out


def test_there_are_transport_comparison_rows_to_check():
    assert {p.stem for p in ROWS} >= {"transport_compare", "transport_varied"}


@pytest.mark.parametrize("path", ROWS, ids=lambda p: p.stem)
def test_a_comparison_row_rebuilds_from_its_committed_runs(path: Path):
    row = json.loads(path.read_text())
    args = _args(row["command"])
    assert "--rows" in args, f"{path.name}: its runs are not committed (no --rows)"
    lines = (ROOT / args["--rows"]).read_text().splitlines()
    committed = {}
    for line in filter(str.strip, lines):
        r = json.loads(line)
        committed[(r["label"], r["scenario"], r["seed"], r["strategy"])] = r
    result = row["result"]
    strategies = tuple(args.get("--strategies", ",".join(STRATEGIES)).split(","))
    checked = 0
    for section, label in SETS:
        if section not in result:
            continue
        runs = result[f"{section}_runs"]
        for r in runs:  # every run of the row is in the committed file, the same run
            key = (label, r["scenario"], r["seed"], r["strategy"])
            assert key in committed, f"{path.name}: {key} not in {args['--rows']}"
            assert committed[key]["success"] == r["success"]
            assert committed[key]["transport_time_s"] == r["transport_time_s"]
        again = aggregate(
            [committed[(label, r["scenario"], r["seed"], r["strategy"])] for r in runs],
            strategies,
            np.random.default_rng(2024),
        )
        assert _strip(again) == _strip(result[section]), f"{path.name}: {section}"
        checked += len(runs)
    assert checked > 0
