"""``fleet log layout [--out F]``: the shipped Foxglove layout.

Without ``--out`` prints the path of ``layout.json`` (in the installed package); with it, writes
a copy there. In Foxglove: open the MCAP file, then Layouts → Import from file → that file. It
opens on a 3D panel with the scene (robots, object, obstacles, capture points, route, pushers),
plots of clearance and speeds, the phase over time, the e-stop state and the log.
"""

from __future__ import annotations

EXAMPLES = """examples:
  fleet log layout                    the path of the shipped layout.json
  fleet log layout --out layout.json  a copy here, to import in Foxglove
"""


def add_arguments(parser, word: str) -> None:
    parser.add_argument("--out", default=None, help="write a copy of the layout here")


def run(args) -> int:
    import shutil
    from pathlib import Path

    from controller.scene import LAYOUT

    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(LAYOUT, args.out)
        print(args.out)
    else:
        print(LAYOUT)
    return 0
