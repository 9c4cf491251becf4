"""The `volsmpl` console command. Each subcommand lives in the module that owns its work and
registers itself through `add_parser(subparsers)`; this file only dispatches.

Only the chosen subcommand's module is imported (`volsmpl --help` and `volsmpl body info` do not
load the training, benchmark or app code)."""
from __future__ import annotations

import argparse
import importlib
import os
import sys
import traceback

from volsmpl.runtime.deps import MissingDependency

# subcommand name -> (module providing add_parser(subparsers) and run(args), one-line summary for --help)
SUBCOMMANDS = {
    "bench": ("volsmpl.bench.run", "time / memory / accuracy benchmark: VolumetricSMPL vs COAP vs winding numbers"),
    "body": ("volsmpl.body.cli", "export / inspect / pose the default body"),
    "demo": ("volsmpl.demo", "pose the default body; meshes, part picture, SDF slice and surfaces"),
    "eval": ("volsmpl.evaluation.cli", "evaluate a checkpoint on the validation set (paper Table 1 columns)"),
    "report": ("volsmpl.report.build", "write docs/report.md: every result table beside the paper's numbers"),
    "motion": ("volsmpl.apps.motion.cli", "scene-constrained walking: VolumetricSMPL vs COAP vs exact mesh (paper Table 5, D.1)"),
    "egohmr": ("volsmpl.apps.egohmr.cli", "egocentric body recovery, collision-guided diffusion: VolumetricSMPL vs COAP vs exact mesh (paper Table 4)"),
    "hoi": ("volsmpl.apps.hoi.cli", "human-object joint optimisation: VolumetricSMPL vs COAP vs exact mesh (paper Table 3)"),
    "selfpen": ("volsmpl.apps.selfpen.cli", "repair self-intersections by pose optimisation (paper Table 6)"),
    "train": ("volsmpl.train.loop", "train the volumetric model on the default body (resumable; torchrun for DDP)"),
}


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser with the full options of `command` (every subcommand when None) and one-line entries
    for the others."""
    parser = argparse.ArgumentParser(prog="volsmpl", description="VolumetricSMPL: neural volumetric human body model")
    parser.add_argument("--debug", action="store_true",
                        help="show the full traceback of an error (also: environment variable VOLSMPL_DEBUG=1)")
    sub = parser.add_subparsers(dest="command", required=True, metavar="{" + ",".join(SUBCOMMANDS) + "}")
    for name, (module, summary) in SUBCOMMANDS.items():
        if command is None or name == command:
            mod = importlib.import_module(module)
            p = mod.add_parser(sub)
            p.set_defaults(_run=mod.run, _parser=p)  # _parser: its defaults tell the options a user gave
        else:
            sub.add_parser(name, help=summary, add_help=False)
    return parser


#: exceptions a user can cause (bad arguments, inputs, paths, environment, a missing package): exit 2, the
#: message is the fix
USER_ERRORS = (ValueError, TypeError, OSError, RuntimeError, MissingDependency)


def _one_line(e: BaseException) -> str:
    msg = " ".join(str(e).split())
    return msg or type(e).__name__


def _debug_env() -> bool:
    return os.environ.get("VOLSMPL_DEBUG", "").strip().lower() not in ("", "0", "false", "no", "off")


def main(argv=None) -> int:
    """Run `volsmpl ARGV`; return the exit code. Every exception of a subcommand ends as one line on stderr,
    `volsmpl <cmd>: error: <message>`: exit 2 for user errors (USER_ERRORS), 1 for unexpected internal errors,
    130 for Ctrl-C. The traceback is printed only with --debug (anywhere on the line) or VOLSMPL_DEBUG=1."""
    argv = sys.argv[1:] if argv is None else list(argv)
    cut = argv.index("--") if "--" in argv else len(argv)
    debug = "--debug" in argv[:cut] or _debug_env()
    argv = [a for i, a in enumerate(argv) if not (a == "--debug" and i < cut)]
    command = next((a for a in argv if not a.startswith("-")), None)
    name = command if command in SUBCOMMANDS else "?"
    try:
        args = build_parser(command if command in SUBCOMMANDS else "").parse_args(argv)
        if getattr(args, "device", None) is not None:  # every --device: runs there, or one line why not
            from volsmpl.runtime.devices import check_device
            check_device(args.device)
        return int(args._run(args) or 0)
    except SystemExit:  # argparse (usage line + error, exit 2; --help exit 0) and explicit exits
        raise
    except KeyboardInterrupt:
        if debug:
            traceback.print_exc()
        print(f"volsmpl {name}: interrupted", file=sys.stderr)
        return 130
    except USER_ERRORS as e:  # user errors: one clear line, no traceback
        if debug:
            traceback.print_exc()
        print(f"volsmpl {name}: error: {_one_line(e)}", file=sys.stderr)
        return 2
    except Exception as e:  # a bug: still one line, the traceback on request
        if debug:
            traceback.print_exc()
        print(f"volsmpl {name}: error: internal error: {type(e).__name__}: {_one_line(e)} "
              f"(rerun with --debug or VOLSMPL_DEBUG=1 to see the traceback)", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
