"""``python -m rig.autopilots.reference --instance I [--param NAME=VALUE ...] [--log PATH]``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from rig.autopilots.reference.params import ParameterError, Parameters, parse_assignment
from rig.autopilots.reference.process import Autopilot
from rig.errors import LogWriteFailed


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m rig.autopilots.reference",
        description="The reference autopilot: connects to the rig on TCP 4560+I like PX4 SITL.",
    )
    parser.add_argument("--instance", type=int, default=0, help="SITL instance I (ports +I)")
    parser.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                        help="set a PX4 parameter (repeatable)")  # fmt: skip
    parser.add_argument("--log", type=Path, help="write the autopilot's ULog here")
    args = parser.parse_args(argv)
    try:
        params = Parameters(dict(parse_assignment(text) for text in args.param))
    except ParameterError as error:
        parser.error(str(error))
    try:
        autopilot = Autopilot(args.instance, params, args.log)
    except (ValueError, OSError) as error:
        parser.error(f"instance {args.instance}: {error}")
    try:
        reason = autopilot.run()
        if reason is not None:
            print(f"rig.autopilots.reference: {reason}; stopping", file=sys.stderr)
    except KeyboardInterrupt:
        pass  # SIGINT before the rig's link is served: close the log cleanly
    except LogWriteFailed as error:  # a full disk: the log is whole up to its last message
        print(f"rig.autopilots.reference: {error}; stopping", file=sys.stderr)
        return 1
    finally:
        autopilot.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
