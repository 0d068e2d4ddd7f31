"""``fleet init`` and the example configs it ships (controller/examples, package data): every
example passes the config checks and is what it says it is; ``fleet init`` writes it, never
over a file without ``--force``; the top-level fleet.toml and lab.toml are the packaged
examples; ``fleet run`` with no config anywhere exits 2 saying how to get one."""

from __future__ import annotations

import fnmatch
import json
import subprocess
import tomllib
from importlib import resources

import pytest

from controller.cli import main
from controller.commands import NO_CONFIG_HERE
from controller.config import load_config
from controller.examples import CATALOG, DEFAULT_KIND, KINDS, example, example_text
from tests.support.config import ROOT
from tests.support.lab import fleet as run_fleet

LAB_KINDS = tuple(k for k in KINDS if k != DEFAULT_KIND)
# fleet.toml's job: what every lab example shares with the dry run
JOB_SECTIONS = ("fleet", "world", "obstacles", "object", "capture", "approach", "route",
                "transport", "estimation")  # fmt: skip
ROBOT_BODY = ("id", "kind", "radius", "max_speed", "max_yaw_rate", "max_force", "start")


def _data(kind: str) -> dict:
    return tomllib.loads(example_text(kind))


def _written(tmp_path, kind: str):
    path = tmp_path / f"{kind}.toml"
    path.write_text(example_text(kind), encoding="utf-8")
    return path


def test_the_catalog_has_the_five_kinds_dry_run_first():
    assert KINDS == ("dry-run", "rehearsal", "mavlink", "ros2", "mixed")
    assert example("dry-run").out == "fleet.toml"
    assert {example(k).out for k in LAB_KINDS} == {"lab.toml"}
    with pytest.raises(KeyError, match="expected one of dry-run"):
        example("lab")


@pytest.mark.parametrize("kind", KINDS)
def test_every_example_passes_fleet_check(kind, tmp_path, monkeypatch, capsys):
    """load_config and ``fleet check --json`` (in process, in an empty folder: log.dir is
    probed there) accept the shipped file, with its six robots and three obstacles."""
    path = _written(tmp_path, kind)
    monkeypatch.chdir(tmp_path)
    cfg = load_config(path)
    assert cfg.robot_ids == ("r1", "r2", "r3", "r4", "r5", "r6")
    assert main(["check", "--config", str(path), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["ok"] is True and out["robots"] == list(cfg.robot_ids) and out["obstacles"] == 3


@pytest.mark.parametrize("kind", LAB_KINDS)
def test_every_lab_example_is_the_dry_runs_job_on_the_lab_bus(kind):
    """The same room, object, planners and robots (ids, kinds, sizes, starts) as fleet.toml;
    the fleet's bus listening on 127.0.0.1:7447 (the e-stop's second path on 7449), logs in
    runs/, sim robots in the shared world process."""
    dry, lab = _data(DEFAULT_KIND), _data(kind)
    for section in JOB_SECTIONS:
        assert lab[section] == dry[section], section
    assert [{k: r[k] for k in ROBOT_BODY} for r in lab["robots"]] == [
        {k: r[k] for k in ROBOT_BODY} for r in dry["robots"]
    ]
    assert lab["zenoh"] == {
        "mode": "peer",
        "listen": ["tcp/127.0.0.1:7447"],
        "connect": [],
        "estop_listen": ["tcp/127.0.0.1:7449"],  # the e-stop's second path (the daemon's)
    }
    assert lab["log"] == {"dir": "runs"}
    assert lab["sim"] == {**dry["sim"], "world": "process"}


def test_the_rehearsal_is_all_sim_robots():
    cfg = load_config_of("rehearsal")
    assert {r.driver for r in cfg.robots} == {"sim"}
    assert cfg.sim.world == "process"


def load_config_of(kind: str):
    from controller.config import parse_config

    return parse_config(_data(kind), f"<{kind}>")


def test_the_mavlink_example_is_rehearsable_with_fleet_world_mavlink():
    """Every robot a MAVLink vehicle on its own UDP url on 127.0.0.1 that ``fleet world
    --mavlink`` can answer; omni ones PX4s, differential ones ArduRovers."""
    from controller.runtime.world import emulated_vehicles

    cfg = load_config_of("mavlink")
    assert {r.driver for r in cfg.robots} == {"mavlink"}
    assert emulated_vehicles(cfg, "all") == cfg.robot_ids
    assert all(r.url.startswith("udpin:127.0.0.1:") for r in cfg.robots)
    assert len({r.url for r in cfg.robots}) == len(cfg.robots)
    assert {r.kind: r.profile for r in cfg.robots} == {"omni": "px4", "diff": "ardurover"}


def test_the_ros2_example_is_rehearsable_with_fleet_world_ros2():
    """Every robot a ROS 2 robot in its own namespace, its router on loopback (off the
    fleet's own port), its odom frame at its start."""
    from controller.runtime.world import ros2_bodies

    cfg = load_config_of("ros2")
    assert {r.driver for r in cfg.robots} == {"ros2"}
    assert ros2_bodies(cfg, "all") == cfg.robot_ids
    assert len({r.ros2.namespace for r in cfg.robots}) == len(cfg.robots)
    for r in cfg.robots:
        assert r.ros2.connect == ("tcp/127.0.0.1:7448",)
        assert r.ros2.odom_to_world == r.start
    assert cfg.notes == ()


def test_the_mixed_example_has_sim_px4_ardurover_and_ros2_robots():
    from controller.runtime.world import emulated_vehicles, ros2_bodies, world_config

    cfg = load_config_of("mixed")
    kinds = {r.id: r.profile or r.driver for r in cfg.robots}
    assert kinds == {"r1": "px4", "r2": "ros2", "r3": "ardurover", "r4": "ros2",
                     "r5": "sim", "r6": "sim"}  # fmt: skip
    assert emulated_vehicles(cfg, "all") == ("r1", "r3")
    assert ros2_bodies(cfg, "all") == ("r2", "r4")
    r4 = cfg.robots[3].ros2  # the other message types, in a domain of its own
    assert (r4.pose_type, r4.cmd_type, r4.domain_id) == ("pose_stamped", "twist_stamped", 3)
    assert [r.id for r in world_config(cfg).robots] == ["r5", "r6"]


def test_the_examples_are_package_data_found_through_importlib_resources():
    """As an installed user would find them: importlib.resources, and pyproject's
    package-data naming every file."""
    root = resources.files("controller.examples")
    for e in CATALOG:
        assert root.joinpath(e.file).is_file(), e.file
        assert root.joinpath(e.file).read_text(encoding="utf-8") == example_text(e.kind)
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    patterns = pyproject["tool"]["setuptools"]["package-data"]["controller.examples"]
    for e in CATALOG:
        assert any(fnmatch.fnmatch(e.file, p) for p in patterns), (e.file, patterns)


@pytest.mark.parametrize(("top", "kind"), [("fleet.toml", "dry-run"), ("lab.toml", "rehearsal")])
def test_the_top_level_configs_are_the_packaged_examples(top, kind):
    """The repository's fleet.toml and lab.toml are copies of the packaged examples (the
    source): after editing one, ``fleet init KIND --out TOP --force`` brings the other along."""
    assert (ROOT / top).read_text(encoding="utf-8") == example_text(kind), (
        f"{top} differs from controller/examples/{example(kind).file}"
    )


# --------------------------------------------------------------------------- fleet init


@pytest.mark.parametrize("kind", KINDS)
def test_fleet_init_writes_the_example_and_names_the_next_command(kind, tmp_path, monkeypatch,
                                                                  capsys):  # fmt: skip
    monkeypatch.chdir(tmp_path)
    assert main(["init", kind]) == 0
    e = example(kind)
    written = tmp_path / e.out
    assert written.read_text(encoding="utf-8") == example_text(kind)
    assert load_config(written).robot_ids == ("r1", "r2", "r3", "r4", "r5", "r6")
    out = capsys.readouterr().out
    assert f"wrote {e.out}" in out
    if kind == DEFAULT_KIND:
        assert "next: fleet run --config fleet.toml" in out.splitlines()
    else:
        lines = out.splitlines()
        assert "next: fleet up --config lab.toml" in lines
        assert "then: fleet resume --config lab.toml" in lines


def test_fleet_init_without_a_kind_writes_the_dry_run(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["init"]) == 0
    assert (tmp_path / "fleet.toml").read_text(encoding="utf-8") == example_text("dry-run")
    assert not (tmp_path / "lab.toml").exists()


def test_fleet_init_never_overwrites_without_force(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    mine = tmp_path / "lab.toml"
    mine.write_text("# my lab\n")
    assert main(["init", "mixed"]) == 2
    err = capsys.readouterr().err
    assert "lab.toml exists: not overwritten" in err and "--force" in err
    assert mine.read_text() == "# my lab\n"
    assert main(["init", "mixed", "--force"]) == 0
    assert mine.read_text(encoding="utf-8") == example_text("mixed")
    # the example already there (the repository's lab.toml): nothing to overwrite, exit 0
    capsys.readouterr()
    assert main(["init", "mixed"]) == 0
    assert "is the mixed example already" in capsys.readouterr().out
    assert main(["init", "rehearsal"]) == 2  # another example's text: refused


def test_fleet_init_out_writes_there_creating_its_folder(tmp_path, capsys):
    out = tmp_path / "a b" / "mav.toml"
    assert main(["init", "mavlink", "--out", str(out)]) == 0
    assert out.read_text(encoding="utf-8") == example_text("mavlink")
    assert f"next: fleet up --config '{out}'" in capsys.readouterr().out  # quoted for a shell


def test_fleet_init_out_a_folder_exits_2(tmp_path, capsys):
    assert main(["init", "--out", str(tmp_path)]) == 2
    assert "a folder" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_fleet_init_an_unknown_kind_exits_2(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exc:
        main(["init", "lab"])
    assert exc.value.code == 2
    assert "invalid choice: 'lab'" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_fleet_init_list_names_every_kind_a_line_each(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["init", "--list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split()[0] for line in lines] == list(KINDS)
    for line, e in zip(lines, CATALOG, strict=True):
        assert e.out in line and e.summary in line
    assert list(tmp_path.iterdir()) == []  # --list writes nothing


def test_the_init_module_documents_itself():
    """A docstring and EXAMPLES (example commands) for --help, each command a real one."""
    from controller.commands import init

    assert init.__doc__ and "fleet init" in init.__doc__
    commands = [line.split("#")[0].split() for line in init.EXAMPLES.splitlines()]
    assert commands and all(c[:2] == ["fleet", "init"] for c in commands)
    for c in commands:
        args = [a for a in c[2:] if not a.startswith("-")]
        assert not args or args[0] in KINDS or c[c.index(args[0]) - 1] == "--out", c


# --------------------------------------------------------------------------- no config


def test_fleet_run_without_a_config_anywhere_exits_2_saying_how_to_get_one(
    tmp_path, monkeypatch, capsys
):
    """No --config and no fleet.toml in the folder: exit 2 naming fleet init, never a
    packaged example run instead (no log written)."""
    monkeypatch.chdir(tmp_path)
    assert main(["run"]) == 2
    assert NO_CONFIG_HERE in capsys.readouterr().err
    assert main(["run", "--json"]) == 2
    out = json.loads(capsys.readouterr().out)
    assert out["ok"] is False and out["error"] == NO_CONFIG_HERE and out["exit"] == 2
    assert list(tmp_path.iterdir()) == []


def test_fleet_check_without_a_config_anywhere_exits_2_saying_how_to_get_one(
    tmp_path, monkeypatch, capsys
):
    monkeypatch.chdir(tmp_path)
    assert main(["check", "--json"]) == 2
    out = json.loads(capsys.readouterr().out)
    assert out == {"ok": False, "file": "fleet.toml", "path": "", "error": NO_CONFIG_HERE}


def test_a_config_given_but_missing_still_names_the_file(tmp_path, monkeypatch, capsys):
    """``--config fleet.toml`` given explicitly is the user's file: the loader's message."""
    monkeypatch.chdir(tmp_path)
    assert main(["run", "--config", "fleet.toml"]) == 2
    err = capsys.readouterr().err
    assert "fleet.toml: <root>: cannot read" in err and NO_CONFIG_HERE not in err


def test_fleet_toml_in_the_folder_is_the_default(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["init"]) == 0
    capsys.readouterr()
    assert main(["check", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["file"] == "fleet.toml"


# --------------------------------------------------------------------------- end to end


@pytest.mark.e2e
def test_fleet_init_then_fleet_run_in_an_empty_folder(tmp_path):
    """A new user's first two commands, in a folder of their own (cwd: not the repository):
    ``fleet init`` then ``fleet run --config fleet.toml --max-time 5 --json`` starts the dry
    run and runs it; 5 s of sim time is too short for the capture, so it ends in a timeout
    failure (exit 1) with its JSON summary, its log in the folder's runs/."""

    def fleet(*args: str) -> subprocess.CompletedProcess:
        return run_fleet(*args, timeout=120, cwd=tmp_path)

    init = fleet("init")
    assert init.returncode == 0, init.stderr
    assert "next: fleet run --config fleet.toml" in init.stdout
    run = fleet("run", "--config", "fleet.toml", "--max-time", "5", "--json")
    assert run.returncode == 1, run.stderr[-2000:]
    out = json.loads(run.stdout)
    assert out["status"] == "failed" and out["failure"]["reason"] == "timeout", out["failure"]
    assert 5.0 <= out["sim_time_s"] < 5.5 and out["ticks"] > 90 and out["missed_ticks"] == 0
    assert out["mission"]["form_closure"] is True  # the capture was planned: the job started
    log = tmp_path / out["log"]
    assert log.parent == tmp_path / "runs" and log.stat().st_size > 0
