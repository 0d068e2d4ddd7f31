"""What planning with the error model costs (issue 34, item 5): prints ONE JSON object.

The same seeded planning cases (``tests.support.transport_cases.push_case``: an L crate, 4, 6 and
8 robots, shuffled by seed) planned by ``sa`` with the default settings, without the error
model (condition 1) and with Yamashita's (condition 2: the motion error's norm 0.041 m as the
push margin and the robots' extra spacing, the object 10 % heavier and rougher, the centre of
mass ±1 cm), in this process one after the other. Per robot count: the median and the largest
plan time (ms), and the ratio of the medians, condition 2 / condition 1.
A closed loop plans once per control interval (0.5 s by default) off the tick.

Usage: ``python bench/error_model.py [--seeds 15]``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from controller.planning.transport import plan_local  # noqa: E402
from controller.planning.transport_model import ObjectModel  # noqa: E402
from controller.planning.transport_types import TransportParams  # noqa: E402
from tests.support.transport_cases import push_case  # noqa: E402

POSITION = (0.04, 0.01)  # m: Yamashita's Table 1
SHARE = 0.1  # mass and floor friction
COM = 0.01  # m


def condition_2(state):
    """The state as the error model plans it: the object heavier and rougher, pushes near a
    vertex not counted."""
    m = state.model
    model = ObjectModel.build(
        m.polygon, m.mass * (1 + SHARE), m.floor_friction * (1 + SHARE), m.contact_friction,
        m.robot_radius, push_margin=math.hypot(*POSITION),
    )  # fmt: skip
    return dataclasses.replace(state, model=model)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=15)
    args = ap.parse_args()
    plain = TransportParams()
    errors = TransportParams(pose_error=math.hypot(*POSITION), com_error=COM)
    out: dict = {"bench": "error_model", "load_average": [round(x, 2) for x in os.getloadavg()]}
    rows = []
    for n in (4, 6, 8):
        got: dict = {}
        for label, params, make in (("condition_1", plain, None), ("condition_2", errors, 1)):
            times = []
            for seed in range(args.seeds):
                st = push_case(n, seed=seed)
                st = condition_2(st) if make else st
                t0 = time.perf_counter()
                plan_local(st, params, np.random.default_rng(seed))
                times.append(time.perf_counter() - t0)
            got[label] = {
                "plan_ms_median": round(1000 * statistics.median(times), 2),
                "plan_ms_max": round(1000 * max(times), 2),
            }
        got["time_ratio"] = round(
            got["condition_2"]["plan_ms_median"] / got["condition_1"]["plan_ms_median"], 3
        )
        rows.append({"robots": n, **got})
    out["plans"] = rows
    out["seeds"] = args.seeds
    out["load_average_end"] = [round(x, 2) for x in os.getloadavg()]
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
