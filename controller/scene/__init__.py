"""The Foxglove view of a run: scene messages derived from the bus (``builder``, pure), the
Foxglove JSON Schemas they follow (``schemas/``, vendored from ``@foxglove/schemas``, MIT) and
the shipped layout (``layout.json``)."""

from pathlib import Path

LAYOUT = Path(__file__).resolve().parent / "layout.json"
