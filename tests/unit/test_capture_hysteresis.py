"""The close_in <-> hold switch has hysteresis (#24 item 7): a robot counts as in contact below
``contact_tolerance`` and as having lost it only above ``release_factor`` times that, so gaps
jittering around the contact threshold (sensor noise, a robot pressing on a heavy object that
shivers) hold the cage instead of flapping between the phases."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from controller.mission.capture_phase import (
    CaptureSettings,
    CaptureState,
    Measures,
    advance,
    entered,
)
from controller.mission.sequence import Cue, Sequencer
from controller.mission.types import Phase

SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
SETTINGS = CaptureSettings(contact_tolerance=0.015, release_factor=2.0, hold_s=2.0, timeout=600)
M = 4


def measures(t: float, gaps, polygon=SQUARE) -> Measures:
    return Measures(
        t=t,
        dist=np.zeros(M),
        preload=np.zeros((M, 2)),
        gap=np.asarray(gaps, float),
        polygon=polygon,
        detouring=False,
    )


def closing_in() -> tuple[CaptureState, Sequencer]:
    """A capture closing in: what it remembers, and the job's phase (its sequencer)."""
    seq = Sequencer(Phase.PLAN)
    for cue in (Cue.READY, Cue.ON_ENVELOPE):  # plan -> approach -> close_in, by the table
        seq.report(0.0, cue)
    return CaptureState(t0=0.0, contact_t=np.full(M, np.nan)), seq


def tick(st: CaptureState, seq: Sequencer, m: Measures, s: CaptureSettings) -> CaptureState:
    """One tick as the capture mission runs it: measure, report, remember the phase entered."""
    rep = advance(st, m, s, seq.phase)
    return entered(rep.state, seq.report(m.t, rep.cue, rep.failure), m)[0]


def run(gaps_per_tick, dt: float = 0.05):
    """Feed the gaps tick by tick; return the phases visited and the final state."""
    st, seq = closing_in()
    phases = [seq.phase]
    for k, gaps in enumerate(gaps_per_tick):
        st = tick(st, seq, measures(k * dt, gaps), SETTINGS)
        if seq.phase != phases[-1]:
            phases.append(seq.phase)
    return phases, st


def test_all_in_contact_enters_hold_and_a_gap_beyond_the_release_band_leaves_it():
    phases, st = run([[0.01] * M, [0.01, 0.01, 0.01, 0.031]])
    assert phases == [Phase.CLOSE_IN, Phase.HOLD, Phase.CLOSE_IN]
    assert st.releases == 1


def test_gaps_jittering_inside_the_band_never_flap_the_phase():
    """Seeded gaps that cross the 1.5 cm contact threshold every few ticks but stay under the
    3 cm release: one entry into hold, no contact lost, on to the arrest (without the band:
    dozens of flaps)."""
    rng = np.random.default_rng(24)
    ticks = [[0.005] * M] + [rng.uniform(0.0, 0.029, M).tolist() for _ in range(200)]
    phases, st = run(ticks)
    assert phases[:3] == [Phase.CLOSE_IN, Phase.HOLD, Phase.ARRESTED]
    assert Phase.CLOSE_IN not in phases[1:]
    assert st.releases == 0
    crossings = sum(np.any(np.asarray(g) >= 0.015) for g in ticks)
    assert crossings > 50  # the jitter does cross the contact threshold, often


def test_the_hold_completes_only_once_every_robot_is_back_within_contact():
    """Inside the band the hold waits (no arrest on a robot 2 cm off), then arrests."""
    away = [[0.01, 0.01, 0.01, 0.02]] * 60  # 3 s with one robot in the band
    back = [[0.01] * M] * 5
    phases, _ = run([[0.01] * M] + away + back)
    assert phases == [Phase.CLOSE_IN, Phase.HOLD, Phase.ARRESTED]


@pytest.mark.parametrize("factor", [1.0, 2.0])
def test_the_band_is_the_release_factor(factor):
    """With no band (factor 1) a gap just over the contact tolerance releases; with 2 it holds."""
    s = replace(SETTINGS, release_factor=factor)
    st, seq = closing_in()
    st = tick(st, seq, measures(0.0, [0.01] * M), s)
    st = tick(st, seq, measures(0.05, [0.01, 0.01, 0.01, 0.02]), s)
    assert seq.phase == (Phase.CLOSE_IN if factor == 1.0 else Phase.HOLD)
