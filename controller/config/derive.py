"""Settings derived from config sections, with each default written once: in the section.

A mission's settings dataclass (SI, ready for the algorithm) marks each field that a config key
sets with :func:`configured`: its default *is* the section's default for that key (converted,
e.g. degrees to radians), and :func:`from_section` fills exactly those fields from a loaded
section. A field without the mark is an internal constant of the settings.

    _APPROACH = ApproachSection()  # the config's defaults

    @dataclass(frozen=True)
    class CaptureSettings:
        hold_s: float = configured(_APPROACH, "hold_s")
        settle_s: float = 0.5  # internal

    CaptureSettings.from_config(cfg) == from_section(CaptureSettings, cfg.approach)
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any, TypeVar

T = TypeVar("T")
CONFIG_KEY = "config_key"
CONVERT = "config_convert"


def configured(section: Any, key: str, convert: Callable[[Any], Any] | None = None) -> Any:
    """A settings field set by config key ``key`` of ``section`` (an instance of the section's
    dataclass with its defaults), its default the section's (through ``convert``)."""
    default = getattr(section, key)
    return dataclasses.field(
        default=convert(default) if convert else default,
        metadata={CONFIG_KEY: key, CONVERT: convert},
    )


def config_fields(cls: type) -> dict[str, tuple[str, Callable[[Any], Any] | None]]:
    """Field name -> (config key, conversion) of the fields :func:`configured` marks."""
    return {
        f.name: (f.metadata[CONFIG_KEY], f.metadata[CONVERT])
        for f in dataclasses.fields(cls)
        if CONFIG_KEY in f.metadata
    }


def from_section(cls: type[T], section: Any, **more: Any) -> T:
    """``cls`` with its configured fields from ``section`` (the rest at their defaults, or as
    given in ``more``)."""
    kwargs: dict[str, Any] = {}
    for name, (key, convert) in config_fields(cls).items():
        value = getattr(section, key)
        kwargs[name] = convert(value) if convert else value
    return cls(**kwargs, **more)
