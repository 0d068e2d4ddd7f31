"""``make run`` ends by saying how to call ``fleet`` directly, and exits with the dry run's
status: the Makefile's recipe run against a stand-in venv whose ``fleet`` only exits."""

from __future__ import annotations

import shutil
import subprocess

import pytest

from tests.support.config import ROOT


@pytest.mark.skipif(shutil.which("make") is None, reason="no make here")
@pytest.mark.parametrize("status", [0, 1, 2])
def test_make_run_tells_where_fleet_is_and_keeps_the_dry_runs_status(tmp_path, status):
    venv = tmp_path / "venv"
    (venv / "bin").mkdir(parents=True)
    fleet = venv / "bin" / "fleet"
    fleet.write_text(f'#!/bin/sh\necho "fake fleet $*"\nexit {status}\n')
    fleet.chmod(0o755)
    (venv / ".installed").touch()  # newer than pyproject.toml: nothing to install
    proc = subprocess.run(
        ["make", "-s", "-C", str(ROOT), "run", f"VENV={venv}"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    # make exits 2 when a recipe fails, naming the recipe's own status
    assert proc.returncode == (0 if status == 0 else 2), proc.stderr
    assert (f"Error {status}" in proc.stderr) == (status != 0), proc.stderr
    lines = proc.stdout.splitlines()
    assert "fake fleet run --config fleet.toml" in lines
    assert lines[-1] == (
        f"fleet is in {venv}/bin: run {venv}/bin/fleet --help, or source {venv}/bin/activate"
    )
