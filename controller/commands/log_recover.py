"""``fleet log recover IN OUT [--json]``: a valid, indexed copy of a log cut short by a crash.

Copies every record before the cut into a finished MCAP file (summary, indexes, footer), which
the standard ``mcap`` reader and other tools open. Prints what was recovered (messages, seconds
of log time). Exit 2 when IN is missing or OUT is IN; a complete IN is copied as is.
"""

from __future__ import annotations

EXAMPLES = """examples:
  fleet log recover runs/demo.mcap runs/demo-fixed.mcap         a valid copy of a cut log
  fleet log recover runs/demo.mcap runs/demo-fixed.mcap --json  what was recovered, as JSON
"""


def add_arguments(parser, word: str) -> None:
    parser.add_argument("input", help="the MCAP file (cut or complete)")
    parser.add_argument("output", help="the copy to write")
    parser.add_argument("--json", action="store_true", help="print one JSON object")


def run(args) -> int:
    from controller.cli import emit_json
    from controller.io.recover import recover

    r = recover(args.input, args.output)  # InputError: exit 2
    if args.json:
        emit_json(r)
    else:
        state = "complete" if r["input_complete"] else f"cut ({r['cut'] or 'no footer'})"
        print(
            f"{r['output']}: {r['messages']} messages on {r['channels']} channels, "
            f"{r['seconds']:.2f} s of log time recovered from {r['input']} ({state})"
        )
    return 0
