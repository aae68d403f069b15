"""``dagsreplay``: re-run pipeline stages from a recorded MCAP log.

Logs are written by ``dagsrun --record``; until the recorder writes them this command only
checks its arguments and says that no log can be replayed yet.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

import tyro

from dynactivegs.errors import DagsError


@dataclass(frozen=True)
class ReplayArgs:
    """Re-run a stage and everything after it from a recorded log."""

    log: tyro.conf.Positional[Path]
    """The MCAP log written by dagsrun --record."""


def run(args: ReplayArgs) -> int:
    if not args.log.is_file():
        raise DagsError(f"log not found: {args.log}; pass the path of an MCAP file written by dagsrun --record")
    raise DagsError("this version of dagsreplay cannot replay logs yet: the MCAP recorder has not landed")


def main(argv: list[str] | None = None) -> int:
    try:
        return run(tyro.cli(ReplayArgs, args=argv, prog="dagsreplay"))
    except DagsError as e:
        print(f"dagsreplay: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
