"""The job's phase sequence (controller/mission/sequence.py): a table of (state, report) →
step covering every way out of every phase, every failure reason, and what a report out of
turn does; and the sequence is the only place the missions change a phase."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from controller.events import FailureEvent, PhaseEvent
from controller.mission import sequence as seq
from controller.mission.factory import build_mission
from controller.mission.job import CaptureJob
from controller.mission.sequence import Cue, Failure, JobState, Measures, next_phase
from controller.mission.types import FleetView, Phase, Reason
from tests.support.config import make_config

P = Phase
# (phase, cue, the phase it leads to): the job's whole map, written out by hand
TABLE = [
    (P.PLAN, Cue.READY, P.APPROACH),
    (P.APPROACH, Cue.ON_ENVELOPE, P.CLOSE_IN),
    (P.CLOSE_IN, Cue.ALL_TOUCHING, P.HOLD),
    (P.HOLD, Cue.CONTACT_LOST, P.CLOSE_IN),
    (P.HOLD, Cue.ESCAPED, P.CLOSE_IN),
    (P.HOLD, Cue.HELD, P.ARRESTED),
    (P.ARRESTED, Cue.CONTACT_LOST, P.CLOSE_IN),
    (P.ARRESTED, Cue.CARRY, P.ROUTE),
    (P.ROUTE, Cue.CAN_PUSH, P.TRANSPORT),
    (P.ROUTE, Cue.CANNOT_PUSH, P.REARRANGE),
    (P.REARRANGE, Cue.ARRANGED, P.TRANSPORT),
    (P.REARRANGE, Cue.RESET, P.REARRANGE),
    (P.REARRANGE, Cue.UNPUSHABLE, P.ROUTE),
    (P.REARRANGE, Cue.DELIVERED, P.DONE),
    (P.TRANSPORT, Cue.CAN_PUSH, P.TRANSPORT),
    (P.TRANSPORT, Cue.CANNOT_PUSH, P.REARRANGE),
    (P.TRANSPORT, Cue.STUCK, P.REARRANGE),
    (P.TRANSPORT, Cue.OFF_ROUTE, P.ROUTE),
    (P.TRANSPORT, Cue.DELIVERED, P.DONE),
    (P.PLAN, Cue.CARRY, P.ROUTE),  # --mission transport: the job entered at route
    (P.APPROACH, Cue.REPLANNED, P.APPROACH),  # a new capture set: the approach again
    (P.CLOSE_IN, Cue.REPLANNED, P.APPROACH),
    (P.HOLD, Cue.REPLANNED, P.APPROACH),
    (P.ARRESTED, Cue.REPLANNED, P.APPROACH),
]
CARRY = seq.SequenceSettings(carry=True, start_after=5.0)


@pytest.mark.parametrize(("phase", "cue", "to"), TABLE, ids=[f"{a}-{c}" for a, c, _ in TABLE])
def test_every_way_out_of_every_phase(phase, cue, to):
    step = next_phase(JobState(phase, 1.0), Measures(7.5, cue), CARRY)
    assert step.state.phase == to and step.state.since == 7.5
    # every transition announces the phase it enters, a segment begun again included
    assert step.events == (PhaseEvent(phase=to, t=7.5),)
    assert step.events[0].to_dict() == {"phase": str(to), "t": 7.5}  # the JSON as always


def test_the_table_is_the_whole_map():
    assert {(a, c): b for a, c, b in TABLE} | {(P.ARRESTED, Cue.SETTLED): P.DONE} == (
        seq.TRANSITIONS
    )


def test_a_capture_alone_ends_settled_and_a_carrying_job_does_not():
    alone = next_phase(JobState(P.ARRESTED), Measures(3.0, Cue.SETTLED))
    assert alone.state.phase == P.DONE
    assert next_phase(JobState(P.ARRESTED), Measures(3.0, Cue.SETTLED), CARRY).state.phase == (
        P.ARRESTED
    )
    # a capture alone never carries
    assert not next_phase(JobState(P.ARRESTED), Measures(3.0, Cue.CARRY)).fired


def test_the_carry_timer_moves_an_arrested_job_to_route_after_start_after():
    """``transport.start_after`` s after the arrest the sequence raises ``carry`` itself; a
    cue that leads somewhere in that tick wins, and the wait starts again at the next arrest."""
    arrested = JobState(P.ARRESTED, 10.0)
    assert not next_phase(arrested, Measures(14.9), CARRY).fired  # 4.9 s: still held
    step = next_phase(arrested, Measures(15.0), CARRY)
    assert step.state == JobState(P.ROUTE, 15.0)
    assert step.events == (PhaseEvent(phase=P.ROUTE, t=15.0),)
    # a cue out of turn (it leads nowhere from arrested) does not hide the timer
    assert next_phase(arrested, Measures(15.0, Cue.ON_ENVELOPE), CARRY).state.phase == P.ROUTE
    # the contact lost in the tick the wait ends: back to close_in, no carry
    lost = next_phase(arrested, Measures(15.0, Cue.CONTACT_LOST), CARRY)
    assert lost.state == JobState(P.CLOSE_IN, 15.0)
    # ... and the timer runs in no other phase
    assert not next_phase(lost.state, Measures(99.0), CARRY).fired
    # a capture alone holds the object: no timer carries it
    assert not next_phase(arrested, Measures(99.0)).fired
    # no goal: the job ends settled instead (carry off)
    assert not next_phase(arrested, Measures(99.0), seq.SequenceSettings(False, 5.0)).fired


@pytest.mark.parametrize("phase", sorted({a for a, _, _ in TABLE}))
def test_a_report_out_of_turn_leaves_the_phase(phase):
    for cue in Cue:
        if (phase, cue) in seq.TRANSITIONS:
            continue
        step = next_phase(JobState(phase, 1.0), Measures(2.0, cue), CARRY)
        assert step.state == JobState(phase, 1.0) and step.events == ()


@pytest.mark.parametrize("reason", list(Reason))
@pytest.mark.parametrize("phase", [p for p in Phase if p not in seq.FINAL])
def test_every_failure_from_every_live_phase(phase, reason):
    step = next_phase(
        JobState(phase), Measures(4.0, Cue.DELIVERED, Failure(reason, "why")), CARRY
    )  # a failure wins over a cue of the same tick
    assert step.state.phase == P.FAILED and step.state.failure == Failure(reason, "why")
    assert step.events == (
        PhaseEvent(phase=P.FAILED, t=4.0),
        FailureEvent(reason=reason, t=4.0, detail="why"),
    )
    assert [e.to_dict() for e in step.events] == [
        {"phase": "failed", "t": 4.0},
        {"reason": str(reason), "t": 4.0, "detail": "why"},
    ]


@pytest.mark.parametrize("phase", sorted(seq.FINAL))
def test_done_and_failed_are_final(phase):
    st = JobState(phase, 1.0)
    for cue in Cue:
        assert next_phase(st, Measures(2.0, cue), CARRY).state == st
    assert next_phase(st, Measures(2.0, None, Failure(Reason.TIMEOUT, "x"))).state == st


def phase_writes(source: str) -> list[str]:
    """Where a module writes a phase (an AST walk, so a line break or an alias cannot hide
    one): an assignment to an attribute ``phase``, a ``phase=`` keyword of ``replace`` or
    ``JobState``, a ``JobState(...)`` built from anything but ``Phase.PLAN``/``APPROACH``/
    ``ARRESTED`` as a stage's first state, or a call of a ``_go`` helper."""
    out = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Assign | ast.AugAssign | ast.AnnAssign):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            for t in targets:
                for sub in ast.walk(t):
                    if isinstance(sub, ast.Attribute) and sub.attr == "phase":
                        out.append(f"{node.lineno}: assigns .phase")
        elif isinstance(node, ast.Call):
            name = getattr(node.func, "id", getattr(node.func, "attr", ""))
            if name == "_go":
                out.append(f"{node.lineno}: calls _go")
            # (an event or an intent names the phase it reports from: data, not a write)
            if any(k.arg == "phase" for k in node.keywords) and name in ("replace", "JobState"):
                out.append(f"{node.lineno}: {name}(phase=...)")
            if name == "JobState" and not _a_first_state(node):
                out.append(f"{node.lineno}: JobState({ast.unparse(node.args[0])})")
    return sorted(out, key=lambda h: int(h.split(":")[0]))


# a stage's first state (the debt issue 35 names: three holders of a JobState, each started
# here and moved only by next_phase); anything else built as a JobState is a phase written
FIRST_STATES = {"Phase.PLAN", "Phase.APPROACH", "Phase.ARRESTED", "self.phase"}


def _a_first_state(call: ast.Call) -> bool:
    return bool(call.args) and ast.unparse(call.args[0]) in FIRST_STATES and len(call.args) == 1


def test_only_the_sequence_changes_a_phase():
    """No mission module writes a phase (``x.phase = ...``, ``replace(..., phase=...)``, a
    ``JobState`` of its own choosing): they report cues and failures, ``next_phase`` moves."""
    root = Path(seq.__file__).parent
    for f in root.glob("*.py"):
        if f.name in ("sequence.py", "types.py", "basic.py"):  # (basic: goto and hold alone)
            continue
        assert phase_writes(f.read_text()) == [], f.name


def test_the_phase_guard_sees_what_a_regex_missed():
    src = (
        "s.job = JobState(\n    Phase.CARRY)\n"
        "x = dataclasses.replace(st,\n  phase=Phase.DONE)\n"
        "a.b.phase = 'done'\n"
        "ok = JobState(Phase.PLAN)\n"
    )
    assert phase_writes(src) == [
        "1: JobState(Phase.CARRY)",
        "3: replace(phase=...)",
        "5: assigns .phase",
    ]


def _view(cfg, t: float, poses: np.ndarray, obj: np.ndarray) -> FleetView:
    n = len(cfg.robots)
    return FleetView(
        t=t,
        ids=tuple(r.id for r in cfg.robots),
        poses=poses,
        velocities=np.zeros((n, 3)),
        stale=np.zeros(n, bool),
        present=np.ones(n, bool),
        object_pose=obj,
        object_velocity=np.zeros(3),
        object_prediction=obj,
        estop=False,
    )


def test_the_transport_mission_is_the_same_job_entered_at_route():
    cfg = make_config(transport=True)
    job = build_mission(cfg, "transport")
    assert isinstance(job, CaptureJob) and job.capture is None
    n = len(cfg.robots)
    far = np.column_stack([np.linspace(1.0, 2.0, n), np.full(n, 11.0), np.zeros(n)])
    obj = np.asarray(cfg.object.start, float)
    # the job waits in ``plan`` until it sees the object (nobody touches it here: no holders)
    first = job.plan(_view(cfg, 0.0, far, None))
    assert first.report.phase == P.PLAN and first.command.stop
    intent = job.plan(_view(cfg, 0.05, far, obj))
    # the carrying starts at route (the route computed at once here: nobody holds the object,
    # so the same tick goes on to re-arrange)
    phases = [e.phase for e in intent.report.events if isinstance(e, PhaseEvent)]
    assert job.transport is not None and phases == ["route", "rearrange"], intent.report.events
    assert all(c is None for c in job.transport.grip.contacts.values())
    with pytest.raises(Exception, match="entered at plan or route"):
        CaptureJob(cfg, np.random.default_rng(0), entry=P.HOLD)


def test_the_job_holds_the_only_phase_and_its_stages_report_into_it():
    """One ``JobState`` in the code: built in the sequence module only (an AST walk over the
    controller), held by the job's ``Sequencer``, which the capture and the transport it
    starts read and report into (the same object: none keeps a phase of its own)."""
    root = Path(seq.__file__).parents[1]
    built = []
    for f in sorted(root.rglob("*.py")):
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.Call):
                name = getattr(node.func, "id", getattr(node.func, "attr", ""))
                if name == "JobState":
                    built.append(f"{f.relative_to(root)}:{node.lineno}")
    assert built and all(b.startswith("mission/sequence.py:") for b in built), built
    cfg = make_config(transport=True)
    job = build_mission(cfg, "transport")
    n = len(cfg.robots)
    far = np.column_stack([np.linspace(1.0, 2.0, n), np.full(n, 11.0), np.zeros(n)])
    job.plan(_view(cfg, 0.05, far, np.asarray(cfg.object.start, float)))
    assert job.transport.seq is job.seq and job.phase == job.transport.phase
    capture = build_mission(make_config())
    capture.plan(_view(make_config(), 0.0, far, np.asarray(cfg.object.start, float)))
    assert capture.inner is not None and capture.inner.seq is capture.seq
    assert capture.phase == P.APPROACH


def test_no_mission_module_over_400_lines():
    """The mission layer stays in rooms a reader can hold: stages, not one class per phase."""
    root = Path(seq.__file__).parent
    sizes = {f.name: len(f.read_text().splitlines()) for f in root.glob("*.py")}
    assert max(sizes.values()) <= 400, sizes


# the stages of the job and of the transport: each reports or returns what it decided, and
# changes nothing but its own state; ``grip`` is the transport's one state value, changed only
# through its own methods (by the transport's hand)
STAGES = ("push", "rearrange", "progress", "roster", "assign", "reach", "outage", "capture_phase")
COORDINATORS = ("job", "transport")


def _pokes(source: str, rooted_at_self: bool = False) -> list[str]:
    """Assignments to an attribute of another object (``grip.actions[i] = ...``,
    ``self.pusher.stuck = 0``): with ``rooted_at_self`` only those into a component the module
    holds (``self.a.b``), else any whose owner is not ``self`` itself."""
    out = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, ast.Assign | ast.AugAssign | ast.AnnAssign):
            continue
        targets = node.targets if isinstance(node, ast.Assign) else [node.target]
        for t in targets:
            for sub in t.elts if isinstance(t, ast.Tuple) else [t]:
                base = sub
                while isinstance(base, ast.Subscript):
                    base = base.value
                if not isinstance(base, ast.Attribute):
                    continue
                owner = base.value
                if isinstance(owner, ast.Name) and owner.id == "self":
                    continue
                root = owner
                while isinstance(root, ast.Attribute | ast.Subscript):
                    root = root.value
                if rooted_at_self and not (isinstance(root, ast.Name) and root.id == "self"):
                    continue
                out.append(f"{node.lineno}: {ast.unparse(sub)}")
    return out


def test_stages_import_no_other_stage_and_change_nothing_but_their_own():
    root = Path(seq.__file__).parent
    for name in (*STAGES, "grip"):
        src = (root / f"{name}.py").read_text()
        imported = {
            n.module for n in ast.walk(ast.parse(src)) if isinstance(n, ast.ImportFrom) and n.module
        }
        others = {f"controller.mission.{s}" for s in STAGES if s != name}
        assert not imported & others, (name, sorted(imported & others))
        assert _pokes(src) == [], name
    for name in COORDINATORS:  # they change a stage by its verbs, never its fields
        assert _pokes((root / f"{name}.py").read_text(), rooted_at_self=True) == [], name


def test_the_boundary_check_sees_a_field_poke():
    src = "grip.actions[i] = a\nself.pusher.stuck = 0\nself.n = 3\nx.y += 1\n"
    assert _pokes(src) == ["1: grip.actions[i]", "2: self.pusher.stuck", "4: x.y"]
    assert _pokes(src, rooted_at_self=True) == ["2: self.pusher.stuck"]


def _entries_into(path: str, fn) -> int:
    """How many times control passes into a function of the file ``path`` from another file
    while ``fn()`` runs (a profile hook on every Python call)."""
    import sys

    count = 0

    def hook(frame, event, arg):
        nonlocal count
        if event == "call" and frame.f_code.co_filename == path:
            caller = frame.f_back
            if caller is None or caller.f_code.co_filename != path:
                count += 1

    sys.setprofile(hook)
    try:
        fn()
    finally:
        sys.setprofile(None)
    return count


def test_one_tick_enters_the_job_module_twice_its_plan_and_its_safety():
    """A tick as the node runs it (``plan`` then ``safety``) enters ``mission/job.py`` from
    outside it twice, in the capture and in the transport: the stages never call back into
    the job (counted by a profile hook: a call into a job.py function from another file)."""
    from controller.mission import job as job_module

    path = job_module.__file__
    cfg = make_config(transport=True)
    n = len(cfg.robots)
    far = np.column_stack([np.linspace(1.0, 2.0, n), np.full(n, 11.0), np.zeros(n)])
    obj = np.asarray(cfg.object.start, float)
    for kind in ("capture", "transport"):
        job = build_mission(cfg, kind)
        for k in range(2):  # the capture (or the carry) under way
            job.safety(_view(cfg, k * 0.05, far, obj), job.plan(_view(cfg, k * 0.05, far, obj)))
        v = _view(cfg, 0.1, far, obj)
        assert _entries_into(path, lambda j=job, v=v: j.safety(v, j.plan(v))) == 2, kind
        assert job.phase in (P.APPROACH, P.REARRANGE, P.ROUTE, P.TRANSPORT), (kind, job.phase)
