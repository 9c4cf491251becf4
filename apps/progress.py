"""Progress bars of the apps: one tqdm bar per loop over cases (or walks, frames, batches), shown on a terminal only.

    for case in progress(cases, "hoi volsmpl", quiet=args.quiet):   # a bar on a terminal; nothing in a log file
        ...
    optimize(..., progress=steps_bar(args.quiet))                   # the harness's per-step bar, same rule

A bar writes to stderr and only when stderr is a terminal, so a run piped to a file, a test or CI prints nothing
extra; `--quiet` turns it off on a terminal too. Bars leave no line behind (`leave=False`): the table printed after
a case stays readable.
"""
from __future__ import annotations

import sys
from typing import Iterable

__all__ = ["progress", "steps_bar", "shown"]


def shown(quiet: bool = False) -> bool:
    """Whether a bar shows: stderr is a terminal and not --quiet."""
    return not quiet and sys.stderr.isatty()


def progress(items: Iterable, desc: str, quiet: bool = False, total: int | None = None, unit: str = "case"):
    """`items` wrapped in a tqdm bar named `desc` (module docstring); the plain iterable where no bar shows.

    Example:
        >>> list(progress([1, 2], "cases", quiet=True))
        [1, 2]
    """
    if not shown(quiet):
        return items
    from tqdm import tqdm

    return tqdm(items, desc=desc, total=total, unit=unit, leave=False, file=sys.stderr, dynamic_ncols=True)


def steps_bar(quiet: bool = False) -> bool | None:
    """The harness's `progress=` argument: None (its own rule: a terminal, 50 iterations or more) or False."""
    return False if quiet else None
