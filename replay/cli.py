"""``dagsreplay``: re-run a stage and everything after it from a recorded MCAP log.

Without ``--set`` it checks that the re-run outputs are identical to the log (exit 0) or
names the first difference (exit 1); with ``--set`` it is a what-if run that reports how
the outputs changed (exit 0). Bad input: one line on stderr, exit 2. See
:mod:`replay.engine`.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from dynactivegs.errors import DagsError
from dynactivegs.pipeline import STAGE_NAMES


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="dagsreplay", description="Re-run a stage and all after it on a log written by "
                                "dagsrun --record; compare with the log, or report a what-if run (--set).")
    p.add_argument("log", type=Path, help="the MCAP log")
    p.add_argument("--from-stage", default="perception", metavar="STAGE",
                   help=f"first stage to re-run: {', '.join(STAGE_NAMES)} (default: perception)")
    p.add_argument("--from-step", type=int, default=0, metavar="K",
                   help="first step compared; steps before it are re-run silently (default: 0)")
    p.add_argument("--to-step", type=int, metavar="M", help="last step replayed (default: the log's last)")
    p.add_argument("--rrd", type=Path, metavar="OUT.rrd", help="write the replayed steps to a Rerun timeline")
    p.add_argument("--record", type=Path, metavar="NEW.mcap", help="write the replayed run as a new log")
    p.add_argument("--set", dest="overrides", action="append", default=[], nargs="+", metavar="KEY=VALUE",
                   help="what-if config overrides, e.g. --set planning.path.motion_weight=0")
    p.add_argument("--progress", action="store_true", help="show a progress bar")
    return p


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    try:
        from replay.engine import replay

        res = replay(args.log, from_stage=args.from_stage, from_step=args.from_step, to_step=args.to_step,
                     overrides=[kv for group in args.overrides for kv in group], rrd=args.rrd, record=args.record,
                     progress=args.progress)
        return res.exit_code
    except DagsError as e:
        print(f"dagsreplay: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
