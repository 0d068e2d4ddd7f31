"""``fleet schema [--out F]``: the JSON Schema of fleet.toml, from the config sections.

The same source as the configuration reference (docs/reference/config.md): every key, its type,
default, rules and description. TOML editors validate and complete a config with it: the shipped
configs start with the Taplo / Even Better TOML directive ``#:schema ./fleet.schema.json``, and
the repository keeps the file beside them (fleet.schema.json). The schema checks what each key can
check alone (unknown keys, types, ranges, choices); the rules between keys are fleet check's.
Without ``--out`` it prints the schema on stdout.
"""

from __future__ import annotations

EXAMPLES = """examples:
  fleet schema                          print the JSON Schema of fleet.toml
  fleet schema --out fleet.schema.json  write it beside fleet.toml (the file its first line names)
"""


def add_arguments(parser, word: str) -> None:
    parser.add_argument("--out", default=None, help="write the schema to this file")


def run(args) -> int:
    from pathlib import Path

    from controller.docs import schema_text

    text = schema_text()
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(text, encoding="utf-8")
        print(args.out)
    else:
        print(text, end="")
    return 0
