"""The `volsmpl` console command. Each subcommand lives in the module that owns its work and
registers itself through `add_parser(subparsers)`; this file only dispatches."""
from __future__ import annotations

import argparse
import importlib
import sys

# subcommand name -> module providing add_parser(subparsers) and run(args)
SUBCOMMANDS = {
    "bench": "volsmpl.bench",
    "body": "volsmpl.body.cli",
    "demo": "volsmpl.demo",
    "eval": "volsmpl.evaluate",
    "selfpen": "volsmpl.apps.selfpen.cli",
    "train": "volsmpl.train",
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="volsmpl", description="VolumetricSMPL: neural volumetric human body model")
    sub = parser.add_subparsers(dest="command", required=True)
    for name, module in SUBCOMMANDS.items():
        mod = importlib.import_module(module)
        p = mod.add_parser(sub)
        p.set_defaults(_run=mod.run)
    return parser


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args._run(args) or 0)
    except (ValueError, FileNotFoundError, RuntimeError) as e:  # user errors: one clear line, no traceback
        print(f"volsmpl {args.command}: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
