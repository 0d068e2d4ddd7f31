"""Defaults in one place (issue 21 item 5): a mission setting that a config key sets takes its
default from the config section (``controller.config.derive.configured``), never a copy of it;
``from_config`` fills exactly those settings from the loaded section; the transport's settings
hold the grip's and the progress's instead of repeating their fields."""

from __future__ import annotations

import dataclasses
import math

import pytest

from controller.config import ApproachSection, CaptureSection, TransportSection, from_section
from controller.config.derive import config_fields
from controller.mission.capture_phase import CaptureSettings
from controller.mission.grip import GripSettings
from controller.mission.progress import ProgressSettings
from controller.mission.transport_settings import TransportSettings
from controller.planning.approach import PlannerParams
from controller.planning.capture import CaptureParams
from controller.planning.transport_types import TransportParams
from tests.support.config import make_config

# every settings dataclass of the missions, with the config section whose keys it may take
SETTINGS = [
    (CaptureSettings, ApproachSection),
    (TransportSettings, TransportSection),
    (ProgressSettings, TransportSection),
    (GripSettings, TransportSection),
    (TransportParams, TransportSection),  # the planners' parameters
    (CaptureParams, CaptureSection),
    (PlannerParams, ApproachSection),
]


def _keys(section: type) -> set[str]:
    return {f.name for f in dataclasses.fields(section)}


@pytest.mark.parametrize(("cls", "section"), SETTINGS, ids=[c.__name__ for c, _ in SETTINGS])
def test_a_setting_named_after_a_config_key_takes_the_configs_default(cls, section):
    """A field with a config key's name (or the key's name less its unit suffix) that is not
    marked ``configured`` would be a default written twice: the config's and its own."""
    configured = config_fields(cls)
    keys = _keys(section)
    for f in dataclasses.fields(cls):
        stem = {f.name, f"{f.name}_deg", f"{f.name}_hz"}
        if stem & keys:
            assert f.name in configured, (
                f"{cls.__name__}.{f.name} repeats the default of [{section.__name__}]"
            )
    for name, (key, convert) in configured.items():
        assert key in keys, (cls.__name__, name, key)
        want = getattr(section(), key)
        got = getattr(cls(), name)
        assert got == (convert(want) if convert else want), (cls.__name__, name)


@pytest.mark.parametrize(("cls", "section"), SETTINGS, ids=[c.__name__ for c, _ in SETTINGS])
def test_the_settings_of_a_default_section_are_the_settings_defaults(cls, section):
    assert from_section(cls, section()) == cls()


def test_from_config_takes_every_configured_key():
    cfg = make_config(
        {
            "approach": {"hold_s": 3.5, "contact_tolerance": 0.02, "timeout": 99.0},
            "transport": {"tolerance": 0.3, "heading_tolerance_deg": 20.0, "stall_timeout": 7.0},
        },
        transport=True,
    )
    cap = CaptureSettings.from_config(cfg)
    assert (cap.hold_s, cap.contact_tolerance, cap.timeout) == (3.5, 0.02, 99.0)
    assert cap.settle_s == CaptureSettings().settle_s  # internal: untouched
    tr = TransportSettings.from_config(cfg)
    assert tr.tolerance == 0.3 and math.isclose(tr.heading_tolerance, math.radians(20.0))
    # the stall timeout lives once, in the progress settings the transport holds
    assert tr.progress.stall_timeout == 7.0 and tr.stall_timeout == 7.0
    assert tr.grip == GripSettings() and tr.progress.corridor == ProgressSettings().corridor
    assert not {f.name for f in dataclasses.fields(TransportSettings)} & (
        {f.name for f in dataclasses.fields(GripSettings)}
        | {f.name for f in dataclasses.fields(ProgressSettings)}
    )  # held, not repeated
