"""The `volsmpl` console command. Each subcommand lives in the module that owns its work and
registers itself through `add_parser(subparsers)`; this file only dispatches.

Only the chosen subcommand's module is imported (`volsmpl --help` and `volsmpl body info` do not
load the training, benchmark or app code)."""
from __future__ import annotations

import argparse
import importlib
import sys

# subcommand name -> (module providing add_parser(subparsers) and run(args), one-line summary for --help)
SUBCOMMANDS = {
    "bench": ("volsmpl.bench", "time / memory / accuracy benchmark: VolumetricSMPL vs COAP vs winding numbers"),
    "body": ("volsmpl.body.cli", "export / inspect / pose the default body"),
    "demo": ("volsmpl.demo", "pose the default body; meshes, part picture, SDF slice and surfaces"),
    "eval": ("volsmpl.evaluate", "evaluate a checkpoint on the validation set (paper Table 1 protocol)"),
    "report": ("volsmpl.report", "write docs/report.md: every result table beside the paper's numbers"),
    "selfpen": ("volsmpl.apps.selfpen.cli", "repair self-intersections by pose optimisation (paper Table 6)"),
    "train": ("volsmpl.train", "train the volumetric model on the default body (resumable; torchrun for DDP)"),
}


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser with the full options of `command` (every subcommand when None) and one-line entries
    for the others."""
    parser = argparse.ArgumentParser(prog="volsmpl", description="VolumetricSMPL: neural volumetric human body model")
    sub = parser.add_subparsers(dest="command", required=True, metavar="{" + ",".join(SUBCOMMANDS) + "}")
    for name, (module, summary) in SUBCOMMANDS.items():
        if command is None or name == command:
            mod = importlib.import_module(module)
            mod.add_parser(sub).set_defaults(_run=mod.run)
        else:
            sub.add_parser(name, help=summary, add_help=False)
    return parser


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    command = next((a for a in argv if not a.startswith("-")), None)
    args = build_parser(command if command in SUBCOMMANDS else "").parse_args(argv)
    try:
        return int(args._run(args) or 0)
    except (ValueError, FileNotFoundError, RuntimeError) as e:  # user errors: one clear line, no traceback
        print(f"volsmpl {args.command}: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
