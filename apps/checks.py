"""Checks of what a user gives an app, made before any work: options that do not apply to the chosen mode, numbers
out of range, the JSON files a user writes, names made from a user's file names, the output folder (one writer at a
time, one app's results), and warnings.

Every check raises ValueError (or FileNotFoundError) with one line naming the option or file and the fix; `volsmpl`
prints it without a traceback (volsmpl.cli). Warnings go to stderr as ``volsmpl <app>: warning: ...`` and into
results.json (`warnings`), so a run that went on past something unusual says so in both places.

    applies(args, "hoi fit", uses={"case", "iters", ...})   # a non-default option outside `uses` is refused
    number(args.lr, "--lr", lo=0, lo_open=True)             # finite and > 0
    doc = read_json(path, "the tuning file", "--tuned")      # names the file when missing, not UTF-8 or not JSON
    stem = safe_name("my room (scan).ply")                  # 'my_room_scan_.ply': a file name on every system
    with claim_out(args.out, "hoi"): ...                    # one writer; another app's results.json is kept
"""
from __future__ import annotations

import contextlib
import hashlib
import json
import math
import re
import sys
from pathlib import Path

__all__ = ["ALWAYS", "applies", "number", "read_json", "safe_name", "warn", "claim_out", "strict_json"]

#: options every mode takes: the subcommand and action, the traceback switch and the parser itself
ALWAYS = frozenset({"command", "action", "debug", "_run", "_parser", "quiet"})


def _flag(dest: str) -> str:
    return "--" + dest.replace("_", "-")


def applies(args, mode: str, uses) -> None:
    """Refuse every option given with a value other than its default that `mode` does not read (`uses`: the dests
    it reads; ALWAYS are read by every mode). A namespace without the parser (built in code, not by `volsmpl`) is
    not checked: its defaults are not known."""
    parser = getattr(args, "_parser", None)
    if parser is None:
        return
    uses = set(uses) | ALWAYS
    extra = [d for d, v in sorted(vars(args).items())
             if d not in uses and not d.startswith("_") and v != parser.get_default(d)]
    if extra:
        flags = ", ".join(_flag(d) for d in extra)
        raise ValueError(f"{flags} {'does' if len(extra) == 1 else 'do'} not apply to `volsmpl {mode}`: drop "
                         f"{'it' if len(extra) == 1 else 'them'} (see `volsmpl {mode.split()[0]} --help`)")


def number(value, flag: str, *, lo: float | None = None, hi: float | None = None, lo_open: bool = False,
           hi_open: bool = False, what: str = "") -> float:
    """`value` if it is a finite number within [lo, hi] (open ends where asked), else ValueError naming `flag`."""
    lo_s = "" if lo is None else f"{'>' if lo_open else '>='} {lo:g}"
    hi_s = "" if hi is None else f"{'<' if hi_open else '<='} {hi:g}"
    want = " and ".join(s for s in (lo_s, hi_s) if s)
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{flag} {value!r} is not a number; give a finite number{' ' + want if want else ''}"
                         f"{' (' + what + ')' if what else ''}") from None
    bad = not math.isfinite(x)
    bad = bad or (lo is not None and (x <= lo if lo_open else x < lo))
    bad = bad or (hi is not None and (x >= hi if hi_open else x > hi))
    if bad:
        raise ValueError(f"{flag} {x:g}: give a finite number{' ' + want if want else ''}"
                         f"{' (' + what + ')' if what else ''}")
    return x


def read_json(path, what: str, flag: str = "") -> object:
    """The JSON document of a file a user gives; one line naming the file (and the option) when it is missing,
    not UTF-8 or not JSON."""
    path = Path(path)
    via = f" ({flag})" if flag else ""
    if not path.is_file():
        raise FileNotFoundError(f"{what} {path}{via} not found; give the path of an existing file (relative to "
                                f"the folder you run in, or absolute)")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as e:
        raise ValueError(f"{what} {path}{via} is not UTF-8 text (byte {e.start}); give a JSON file") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise ValueError(f"{what} {path}{via} is not valid JSON: {e.msg} at line {e.lineno} column {e.colno}") from None


def safe_name(text: str, limit: int = 48) -> str:
    """A file-name-safe, short form of a name taken from a user's file or case: characters other than ASCII
    letters, digits, '.', '_', '-', '=' and '+' become '_'; a name longer than `limit` (or changed) keeps its
    first characters and gets 8 hex digits of its sha256, so two different names never share a file.

    >>> safe_name("room_3")
    'room_3'
    >>> safe_name("my room")
    'my_room-124ab5fb'
    """
    text = str(text)
    clean = re.sub(r"[^A-Za-z0-9_.=+-]", "_", text).strip(".") or "case"
    if clean == text and len(text) <= limit:
        return text
    digest = hashlib.sha256(text.encode("utf-8", "surrogatepass")).hexdigest()[:8]
    return f"{clean[: max(1, limit - 9)]}-{digest}"


def warn(app: str, text: str, into: list | None = None) -> str:
    """Print one warning line to stderr and append it to `into` (results.json's `warnings`)."""
    line = " ".join(str(text).split())
    print(f"volsmpl {app}: warning: {line}", file=sys.stderr, flush=True)
    if into is not None:
        into.append(line)
    return line


@contextlib.contextmanager
def claim_out(out, app: str):
    """Hold OUT for one run of `app`: a second run writing OUT at the same time stops in one line
    (volsmpl.io.outputs.exclusive_folder), and an OUT whose results.json another app wrote is refused (its results
    would be replaced)."""
    from volsmpl.io.outputs import exclusive_folder

    out = Path(out)
    res = out / "results.json"
    if res.is_file():
        try:
            other = json.loads(res.read_text(encoding="utf-8")).get("app")
        except (ValueError, AttributeError):
            raise ValueError(f"{res} is not a results.json of volsmpl (not JSON); choose another --out or remove "
                             f"it") from None
        if other is not None and other != app:
            raise ValueError(f"--out {out} holds the results of `volsmpl {other}`; choose another --out for "
                             f"`volsmpl {app}` (or remove {res})")
    with exclusive_folder(out, f"volsmpl {app} run"):
        yield out


def strict_json(obj):
    """`obj` with every non-finite float (NaN, inf) replaced by None: results.json is standard JSON, where a
    measure that has no value is null."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: strict_json(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [strict_json(v) for v in obj]
    return obj
