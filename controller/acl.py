"""``python -m controller.acl CONFIG [OUT]``: print (or write) the lab ACL profile's block.

The generator lives in controller/config/acl.py (the config package); its names are re-exported
here for existing importers."""

from __future__ import annotations

import sys

from controller.config import ConfigError, load_config
from controller.config.acl import acl_for, acl_json5, write_acl

__all__ = ["acl_for", "acl_json5", "main", "write_acl"]


def main(argv: list[str] | None = None) -> int:
    """``python -m controller.acl CONFIG [OUT]``: print (or write) the lab profile's block."""
    args = sys.argv[1:] if argv is None else argv
    if not 1 <= len(args) <= 2:
        print("usage: python -m controller.acl CONFIG [OUT.json5]", file=sys.stderr)
        return 2
    try:
        cfg = load_config(args[0])
    except ConfigError as exc:
        print(f"controller.acl: {exc}", file=sys.stderr)
        return 2
    if len(args) == 2:
        write_acl(cfg, args[1])
    else:
        sys.stdout.write(acl_json5(cfg))
    return 0


if __name__ == "__main__":
    sys.exit(main())
