"""``fleet init [KIND] [--out F] [--force] [--list]``: write an example config to start from.

The examples ship with the package (``controller/examples/``), so this works from any folder
after ``pip install``. KIND: ``dry-run`` (the default: ``fleet.toml``, the dry run of ``fleet
run``), ``rehearsal`` (the lab rehearsed on one machine), ``mavlink`` (MAVLink robots),
``ros2`` (ROS 2 robots over rmw_zenoh), ``mixed`` (sim, PX4, ArduRover and ROS 2 robots); the
lab kinds write ``lab.toml`` by default. Each file is commented for a lab user: what each
section is, the units, what to change for real robots, the commands to run. An existing file
is never overwritten without ``--force`` (exit 2). Beside it, unless one is there already, the
JSON Schema its first line names (``#:schema ./fleet.schema.json``: TOML editors validate and
complete the file with it; ``fleet schema`` writes the same). Prints the files written and the
command to run next.
"""

from __future__ import annotations

from pathlib import Path

from controller.config.schema import SCHEMA_FILE
from controller.examples import CATALOG, DEFAULT_KIND, KINDS, example, example_text, next_lines

EXAMPLES = """\
  fleet init                          # fleet.toml: the dry run; then fleet run --config fleet.toml
  fleet init rehearsal                # lab.toml: the lab rehearsed on this machine
  fleet init mavlink --out mav.toml   # MAVLink robots, written to mav.toml
  fleet init mixed --force            # replace an existing lab.toml
  fleet init --list                   # the kinds, a line each
"""


def add_arguments(parser, word: str) -> None:
    parser.add_argument(
        "kind",
        nargs="?",
        default=DEFAULT_KIND,
        choices=KINDS,
        metavar="KIND",
        help=f"one of {', '.join(KINDS)} (default: {DEFAULT_KIND}; --list says what each is)",
    )
    parser.add_argument(
        "--out",
        help="the file to write (default: fleet.toml for dry-run, lab.toml for the others)",
    )
    parser.add_argument("--force", action="store_true", help="overwrite an existing file")
    parser.add_argument("--list", action="store_true", help="list the kinds and exit")


def run(args) -> int:
    from controller.config import InputError

    if args.list:
        width = max(len(k) for k in KINDS)
        for e in CATALOG:
            print(f"{e.kind:<{width}}  {e.out:<10}  {e.summary}")
        return 0
    ex = example(args.kind)
    out = Path(args.out or ex.out)
    if out.is_dir():
        raise InputError(f"--out {out}: a folder; give a file name (e.g. {out / ex.out})")
    text = example_text(args.kind)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        with open(out, "w" if args.force else "x", encoding="utf-8") as f:
            f.write(text)
    except FileExistsError:
        if out.read_bytes() == text.encode("utf-8"):  # the example already: nothing to do
            print(f"fleet init: {out} is the {ex.kind} example already")
            print("\n".join(next_lines(ex, str(out))))
            return 0
        raise InputError(
            f"{out} exists: not overwritten (fleet init {ex.kind} --force replaces it, "
            "--out F writes another file)"
        ) from None
    except OSError as exc:
        raise InputError(f"cannot write {out}: {exc.strerror or exc}") from exc
    print(f"fleet init: wrote {out}, the {ex.kind} example")
    schema = out.parent / SCHEMA_FILE  # what the example's first line names
    if not schema.exists():
        from controller.docs import schema_text

        try:
            schema.write_text(schema_text(), encoding="utf-8")
            print(f"fleet init: wrote {schema}, the schema TOML editors check {out.name} with")
        except OSError as exc:  # the config is what counts: say so and go on
            print(f"fleet init: {schema} not written ({exc.strerror or exc})")
    print("\n".join(next_lines(ex, str(out))))
    return 0
