"""A CLI that teaches (issue 30 item 6): every subcommand's --help describes it and shows an
example, every option says what it does, and ``fleet --version`` answers."""

from __future__ import annotations

import argparse
import subprocess
import sys
import tomllib

import pytest

from controller.cli import build_parser, main, version
from tests.support.config import ROOT


def _subcommands(parser: argparse.ArgumentParser, words: tuple[str, ...] = ()):
    """(words, parser) of every subcommand and group under ``parser``, depth first."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield (*words, name), sub
                yield from _subcommands(sub, (*words, name))


SUBCOMMANDS = list(_subcommands(build_parser()))
IDS = [" ".join(w) for w, _ in SUBCOMMANDS]


def test_the_walk_finds_every_command_and_group():
    names = {" ".join(w) for w, _ in SUBCOMMANDS}
    assert {"run", "check", "driver", "status", "estop", "plan", "plan route", "log"} <= names
    assert "log layout" in names and len(names) >= 18


@pytest.mark.parametrize("words,parser", SUBCOMMANDS, ids=IDS)
def test_every_subcommand_describes_itself_with_an_example(words, parser):
    assert parser.description and parser.description.strip(), words
    assert "``" not in parser.description  # the docstring's reST quoting is left out
    assert not parser.description.startswith("fleet "), "the synopsis is argparse's usage"
    assert parser.epilog and "fleet " in parser.epilog, words
    assert f"fleet {' '.join(words)}" in parser.epilog, "an example of this very command"
    text = parser.format_help()
    assert parser.description.splitlines()[0] in text and parser.epilog.splitlines()[-1] in text


@pytest.mark.parametrize("words,parser", SUBCOMMANDS, ids=IDS)
def test_every_argument_has_help(words, parser):
    for action in parser._actions:
        if isinstance(action, argparse._HelpAction | argparse._SubParsersAction):
            continue
        assert action.help and action.help.strip(), (words, action.option_strings or action.dest)


def test_top_level_help_says_where_to_start(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["--help"])
    assert exit_.value.code == 0
    out = capsys.readouterr().out
    tail = out[out.index("start here:") :]
    assert "fleet run" in tail and "fleet check --config F" in tail


def test_version_prints_the_distribution_version_and_exits_0(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0
    with open(ROOT / "pyproject.toml", "rb") as f:
        expected = tomllib.load(f)["project"]["version"]
    assert capsys.readouterr().out == f"fleet {expected}\n"
    assert version() == expected


def test_version_without_the_distribution_falls_back_to_pyproject(monkeypatch):
    from importlib import metadata

    def missing(name):
        raise metadata.PackageNotFoundError(name)

    monkeypatch.setattr(metadata, "version", missing)
    with open(ROOT / "pyproject.toml", "rb") as f:
        assert version() == tomllib.load(f)["project"]["version"]


def test_version_from_the_command_line():
    out = subprocess.run(
        [sys.executable, "-m", "controller.cli", "--version"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 0 and out.stdout.startswith("fleet ") and out.stderr == ""


def test_driver_waits_a_minute_for_its_robot_by_default():
    args = build_parser().parse_args(["driver", "r1"])
    assert args.connect_timeout == 60.0
    assert (
        build_parser().parse_args(["driver", "r1", "--connect-timeout", "5"]).connect_timeout == 5
    )
