"""`volsmpl report`: every result table beside the paper's numbers, in one Markdown file.

    volsmpl report [--out docs/report.md] [--results NAME=PATH ...] [--check] [--verify NAME=PATH ...]
                   [--baseline NAME=PATH ...]

Reads the result JSONs that `volsmpl eval`, `volsmpl bench`, `volsmpl selfpen` and the apps write (nothing is
run, nothing is fetched), and writes docs/report.md: per section our tables beside the paper's (volsmpl.report.paper),
the figures, and where each result came from (checkpoint, device, commit, date; "not recorded" where a JSON
lacks them). A result is flagged stale when the code that produces it changed after it was made: the commit
recorded in the JSON (else its recorded date, else the commit that last touched the JSON file itself, else the
file's mtime) is compared with `git log -1 -- <producer paths>`, the producer paths being the section's code, every
repository module it imports (volsmpl.report.import_closure: an app's table goes stale when core code it calls changes)
and the default body's data; a stale result is current again when some of its
cases, made again at or after the producer's last change, agree with it (`--verify NAME=PATH` stores that check
beside the result: volsmpl.report.result_check; on another machine `--baseline NAME=PATH` chains it through a run of the
last checked code there). Without git the report says so. The sections
missing results are listed with the command that produces each. --check exits 1 when a result is stale or
missing.

Sections live in SECTIONS (name -> Section: title, paper tables, producer paths, result name -> default paths,
commands, builder, figures); an app adds its section with one entry, usually with the generic
`report_sections.summary_section` (a table from the result's `summary.<back-end>` beside the paper's rows).
"""
from __future__ import annotations

import datetime as _dt
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from volsmpl.report import sections as rs
from volsmpl.report.git import Git
from volsmpl.report.previous import HEADLINES, previous_table
from volsmpl.report.import_closure import producer_closure
from volsmpl.io.outputs import check_writable, write_atomic
from volsmpl.report.result_check import chain_check, check_for, check_path, write_check

_HERE = Path(__file__).resolve().parents[2]
#: the repository root of the source checkout (core/ -> root); else (an installed package) the working directory
ROOT = _HERE if (_HERE / "pyproject.toml").exists() else Path.cwd()


@dataclass(frozen=True)
class Section:
    """One report section. results: result name -> default path(s) relative to the repository root (the first
    that exists is read); the first result is the section's main one. commands: result name -> the command that
    produces it. producer: repository paths of the code that writes the results (staleness; with every module
    they import, volsmpl.report.import_closure, and the default body's data files). checkpoints:
    repository paths of the checkpoints the results may describe (a later change is noted). records: (record
    name, result name, path) of the results kept from the models shipped before (volsmpl.report.previous): shown
    beside their result where the file exists, never stale, never missing."""
    title: str
    paper: tuple
    producer: tuple
    results: dict
    commands: dict
    build: Callable
    figures: tuple = ()
    checkpoints: tuple = ()
    records: tuple = ()


_CKPTS = ("core/assets/volsmpl_anny.safetensors", "core/assets/coap_anny.safetensors")
#: the shipped model's training checkpoint (learned code refinement, docs/learned_refinement.md), the model its
#: passes refine, the one-pass model, and the model shipped before it (tools/app_cost.py's base)
_REFINER = "checkpoints/volsmpl_r3/ckpt-00057000/model"
_BASE = "checkpoints/volsmpl_b8q/ckpt-00050000/model"
_R1 = "checkpoints/volsmpl_r1/ckpt-00053000/model"
_S33000 = "checkpoints/volsmpl_s33000/model"
#: the default body's data: every result poses it
_BODY_DATA = ("core/assets/anny_body.json", "core/assets/anny_shapes.npz", "core/assets/anny_smpl_neutral.npz",
              "core/assets/anny_smplx_neutral.npz")


def _app(name: str, tables: tuple, title: str, build: Callable = rs.summary_section, command: str | None = None,
         more: dict | None = None, figures: tuple = (), tune: bool = False) -> Section:
    """An app's section: its docs/<name>/results.json (else out/<name>/results.json), tabulated by `build`; with
    `tune` its tuning sweep docs/<name>/tune.json (`volsmpl <name> tune`); `more`: further results, name -> (path,
    command)."""
    more = {**({f"{name}_tune": (f"docs/{name}/tune.json", f"volsmpl {name} tune --out docs/{name}")} if tune else {}),
            **(more or {})}
    results = {name: (f"docs/{name}/results.json", f"out/{name}/results.json"), **{k: p for k, (p, _) in more.items()}}
    commands = {name: command or f"volsmpl {name} --out out/{name}", **{k: c for k, (_, c) in more.items()}}
    records = ((f"{name}_previous", name, f"docs/{name}/results_previous.json"),)
    return Section(title, tables, (f"apps/{name}",), results, commands, build, figures, _CKPTS, records)


SECTIONS: dict[str, Section] = {
    "eval": Section(
        "Volumetric bodies: accuracy", ("1",),
        ("core/evaluation", "docs/scripts/refiner_cost.py"),
        {"eval_volsmpl": "docs/eval_volsmpl_anny.json", "eval_coap": "docs/eval_coap_anny.json",
         "refiner_cost": "docs/refiner_cost.json"},
        {"eval_volsmpl": "volsmpl eval --out docs/eval_volsmpl_anny.json",
         "eval_coap": "volsmpl eval --checkpoint core/assets/coap_anny --out docs/eval_coap_anny.json",
         "refiner_cost": f"python docs/scripts/refiner_cost.py --checkpoint {_S33000} {_BASE} {_R1} {_REFINER} "
                         f"--refine-steps 0 1 --out docs/refiner_cost.json"},
        rs.eval_section, ("docs/surfaces.png", "docs/sdf_slice.png"), _CKPTS,
        (("eval_volsmpl_previous", "eval_volsmpl", "docs/eval_volsmpl_previous.json"),
         ("eval_coap_previous", "eval_coap", "docs/eval_coap_previous.json"))),
    "app_cost": Section(
        "Volumetric bodies: cost in the apps", ("3", "4", "5", "6"), ("apps", "tools/app_cost.py"),
        {"app_cost": "docs/app_cost.json"},
        {"app_cost": "python tools/app_cost.py --rounds 3 --threads 1 --out docs/app_cost.json"},
        rs.app_cost_section, (), _CKPTS + tuple(c + ".safetensors" for c in (_S33000, _BASE, _R1, _REFINER))),
    "bench": Section(
        "Volumetric bodies: time and memory; winding numbers", ("1", "C.4"),
        ("core/bench", "core/runtime/meter.py"),
        {"bench": "docs/bench_cpu.json", "bench_cuda": "docs/bench_cuda.json"},
        {"bench": "volsmpl bench --threads 1 --models volsmpl,volsmpl-encoder,volsmpl-grouped,volsmpl-onechunk,"
                  "volsmpl-dense,coap,coap-sparse --out docs/bench_cpu.json --markdown docs/bench_cpu.md",
         "bench_cuda": "volsmpl bench --device cuda --models volsmpl,volsmpl-encoder,volsmpl-dense,coap --batch 1 8 "
                       "--repeats 10 --budget 5 --quick --no-bodybody --out docs/bench_cuda.json --markdown "
                       "docs/bench_cuda.md"},
        rs.bench_section, (), _CKPTS),
    "selfpen": _app("selfpen", ("6",), "Self-intersection repair", rs.selfpen_section,
                    "volsmpl selfpen --model volsmpl,coap,mesh --out out/selfpen",
                    {"selfpen_seeds": ("docs/selfpen/seeds.json",
                                       "for S in 0 1 2 3; do volsmpl selfpen --model volsmpl,coap --sampler-seed $S "
                                       "--out out/selfpen_s$S; done; python tools/selfpen_seeds.py")},
                    (), tune=True),   # the figures: those results.json lists
    "hoi": _app("hoi", ("3",), "Human-object reconstruction", rs.hoi_section,
                command="volsmpl hoi --model volsmpl,coap,mesh --split test --out out/hoi"),
    "egohmr": _app("egohmr", ("4",), "Human mesh recovery in 3D scenes (EgoHMR)", rs.egohmr_section,
                   command="volsmpl egohmr sample --split test --tuned docs/egohmr/tune.json --out out/egohmr"),
    "motion": _app("motion", ("5", "D.1"), "Scene-constrained motion synthesis", rs.motion_section,
                   "volsmpl motion tune --model volsmpl,coap,mesh --scenes all --published-cost --out out/motion",
                   more={"motion_paired": ("docs/motion/paired.json", "python -m volsmpl.apps.motion.stats "
                                           "docs/motion/results.json --out docs/motion/paired.json")}),
}


#: the eval section's row labels of its results (volsmpl.report.previous)
_EVAL_LABELS = {"eval_volsmpl": "VolumetricSMPL", "eval_coap": "COAP"}


def result_names(sections: dict | None = None) -> list[str]:
    return [r for s in (sections or SECTIONS).values() for r in s.results]


# ------------------------------------------------------------------------------------------------------ provenance

def _first(d: dict, *keys):
    for k in keys:
        v = rs.get_path(d, k)
        if v not in (None, "", {}):
            return v
    return None


def provenance(data: dict) -> dict:
    """checkpoint, device, commit, date of a result JSON ('not recorded' where absent)."""
    ck = _first(data, "meta.checkpoint", "checkpoint", "extra.checkpoint", "checkpoints", "config.checkpoints",
                "meta.checkpoints")
    if ck is None and isinstance(data.get("models"), dict):  # volsmpl bench: models.<name>.checkpoint
        ck = {m: r["checkpoint"] for m, r in data["models"].items() if isinstance(r, dict) and r.get("checkpoint")}
    if isinstance(ck, dict):
        ck = ", ".join(f"{k}: {v}" for k, v in ck.items()) or None
    out = {"checkpoint": ck, "device": _first(data, "meta.device", "device", "config.device"),
           "commit": _first(data, "meta.git_commit", "meta.commit", "git_commit", "commit"),
           "date": _first(data, "meta.date", "date")}
    return {k: ("not recorded" if v is None else str(v)) for k, v in out.items()}


def _day(ts: float) -> str:
    return _dt.datetime.fromtimestamp(ts, _dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")


def staleness(path: Path, prov: dict, section: Section, git: Git) -> tuple[str, str]:
    """('current' | 'stale' | 'unknown', explanation) of one result against its producer code; a stale result is
    current again when a re-run check of this very file (`volsmpl.report.result_check`) made at or after the producer's
    last change agrees with it."""
    verdict, why = _staleness(path, prov, section, git)
    check = check_for(path) if verdict == "stale" else None
    if check is None:
        return verdict, why
    at = check.get("fresh_commit")
    if not (at and git.commit_time(at) is not None):
        return verdict, f"{why}; its re-run check records no commit of this repository"
    later = git.last_change(producer_paths(section, git), since=at)
    if later:
        return verdict, f"{why}; its re-run check (at {at}) predates {later[0]}"
    if not check.get("agree"):
        return verdict, (f"{why}; a re-run at {at} disagrees on {check.get('n_mismatches')} values of "
                         f"{check.get('cases_compared')} cases (e.g. {_mismatch(check)})")
    base = (f" with the code of {check['baseline']['commit']} on one machine ({check['machine']['cpu']}; the table's "
            f"machine: {check['machine']['stored_cpu']}), whose own check at {check['chained_from']['fresh_commit']} "
            f"agreed with the table") if check.get("baseline") else ""
    added = (f"; {check['n_added']} values only the re-run records, fields the table predates (e.g. "
             f"{', '.join(check.get('added', [])[:3])})") if check.get("n_added") else ""
    return "current", (f"re-run check at {at} (not before the producer's last change): {check['cases_compared']} of "
                       f"{check['cases_total']} cases made again, all {check['values_compared']} values agree{base}{added} "
                       f"(rel. {check['rel_tol']:g}; times and memory are not compared); {why}")


def _changed(git: Git, since: str, paths) -> str:
    """The producer files changed after commit `since`, a few named (the result's own code, or code it imports)."""
    files = git.changed_files(since, paths)
    shown = ", ".join(files[:4]) + (f" and {len(files) - 4} more" if len(files) > 4 else "")
    return shown or "files since removed"


def producer_paths(section: Section, git: Git) -> tuple[str, ...]:
    """The section's producer paths, the repository modules they import (transitively) and the body's data."""
    return producer_closure(section.producer + _BODY_DATA, git.root)


def _mismatch(check: dict) -> str:
    m = (check.get("mismatches") or [{}])[0]
    return f"{m.get('case')}: {m.get('value')} {m.get('stored')} -> {m.get('fresh')}"


def _staleness(path: Path, prov: dict, section: Section, git: Git) -> tuple[str, str]:
    """staleness by commits and dates alone."""
    if not git.available:
        return "unknown", f"not checked: git unavailable ({git.reason})"
    paths = producer_paths(section, git)
    code = git.last_change(paths)
    if code is None:
        return "unknown", f"not checked: {', '.join(section.producer)} has no commit in this repository"
    dirty = " (the producer code also has uncommitted changes)" if git.dirty(paths) else ""
    commit = prov["commit"] if prov["commit"] != "not recorded" else None
    if commit and git.commit_time(commit) is not None:
        later = git.last_change(paths, since=commit)
        if later:
            return "stale", f"made at commit {commit}; the producer code changed after it ({_changed(git, commit, paths)}): " \
                            f"last {later[0]} ({_day(later[1])}) {later[2]}{dirty}"
        return "current", f"made at commit {commit}, after the last change of the producer code ({code[0]}){dirty}"
    when, basis = None, ""
    if prov["date"] != "not recorded":
        try:
            when, basis = _dt.datetime.fromisoformat(prov["date"]).timestamp(), "recorded date"
        except ValueError:
            pass
    rel = _rel_to(path, git.root)
    if when is None and rel is not None and not git.dirty([rel]):
        own = git.last_change([rel])
        if own:
            when, basis = own[1], f"committed in {own[0]} (no commit or date recorded in the file)"
    if when is None:
        when, basis = path.stat().st_mtime, "file modification time (no commit or date recorded, file not committed)"
    if code[1] > when:
        return "stale", f"{basis} {_day(when)}; the producer code changed later: {code[0]} ({_day(code[1])}) " \
                        f"{code[2]}{dirty}"
    return "current", f"{basis} {_day(when)}, not before the last change of the producer code " \
                      f"({code[0]}, {_day(code[1])}){dirty}"


def _rel_to(path: Path, root: Path) -> str | None:
    try:
        return str(path.resolve().relative_to(Path(root).resolve()))
    except ValueError:
        return None


# ---------------------------------------------------------------------------------------------------------- loading

def load_json(path: Path) -> dict:
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ValueError(f"cannot read result JSON {path}: {e}") from None
    if not isinstance(data, dict):
        raise ValueError(f"result JSON {path} holds a {type(data).__name__}, not an object")
    return data


def parse_overrides(items, sections: dict | None = None, flag: str = "--results") -> dict[str, Path]:
    """--results NAME=PATH ... -> {name: path}; unknown names and missing files are user errors."""
    known, out = result_names(sections), {}
    for item in items or []:
        name, sep, path = item.partition("=")
        if not sep or not name or not path:
            raise ValueError(f"{flag} {item!r}: give NAME=PATH (names: {', '.join(known)})")
        if name not in known:
            raise ValueError(f"{flag} {name}: unknown result name (names: {', '.join(known)})")
        if not Path(path).is_file():
            raise FileNotFoundError(f"{flag} {name}={path}: file not found")
        _same_app(name, Path(path), sections or SECTIONS, flag)
        out[name] = Path(path)
    return out


def _same_app(name: str, path: Path, sections: dict, flag: str) -> None:
    """A results.json that names its app (volsmpl.apps.table's envelope) is refused for another app's section."""
    key = next(k for k, s in sections.items() if name in s.results)
    if name != key:
        return   # a section's further results (seeds, tuning sweeps, paired differences) have no envelope
    data = load_json(path)
    app = data.get("app")
    if isinstance(app, str) and app != key:
        raise ValueError(f"{flag} {name}={path} is a results.json of `volsmpl {app}`, not of `volsmpl {key}`: give "
                         f"{key}'s results (or {app}={path})")


def _locate(default, root: Path) -> Path | None:
    cands = (default,) if isinstance(default, str) else tuple(default)
    return next((root / c for c in cands if (root / c).is_file()), None)


# -------------------------------------------------------------------------------------------------------- rendering

def _link(path: Path, out_dir: Path) -> str:
    return Path(os.path.relpath(Path(path).resolve(), Path(out_dir).resolve())).as_posix()


def _figures(section: Section, results: dict, paths: dict, root: Path) -> list[Path]:
    figs = [root / f for f in section.figures]
    for name, data in results.items():
        f = data.get("figures") if isinstance(data, dict) else None
        f = list(f.values()) if isinstance(f, dict) else (f if isinstance(f, list) else [])
        for x in f:
            p = Path(str(x))
            cand = [p] if p.is_absolute() else [paths[name].parent / p, root / p]
            figs.append(next((c for c in cand if c.exists()), cand[0]))
    return figs


def build_report(out_path: Path, root: Path = ROOT, overrides: dict | None = None, sections: dict | None = None,
                 git: Git | None = None) -> tuple[str, dict]:
    """The report's Markdown and {'stale': [...], 'missing': [...], 'unknown': [...]} (result names)."""
    sections = SECTIONS if sections is None else sections
    root, overrides = Path(root), overrides or {}
    git = Git(root) if git is None else git
    out_dir = Path(out_path).resolve().parent
    status = {"stale": [], "missing": [], "unknown": []}
    body, summary, missing = [], [], []
    for key, sec in sections.items():
        paths = {n: overrides.get(n) or _locate(d, root) for n, d in sec.results.items()}
        results = {n: (load_json(p) if p is not None else None) for n, p in paths.items()}
        tables = ("Tables " if len(sec.paper) > 1 else "Table ") + ", ".join(sec.paper)
        head = f"## {sec.title} (paper {tables}; `{key}`)"
        for n, p in paths.items():
            if p is None:
                missing.append(f"- {tables}, `{n}`: `{sec.commands.get(n, '?')}`")
                status["missing"].append(n)
        main = next(iter(sec.results))
        if all(r is None for r in results.values()):
            summary.append([f"[{sec.title}](#{key})", tables, "missing", f"`{sec.commands.get(main, '?')}`"])
            body += [f'<a id="{key}"></a>', "", head, "",
                     f"No results yet: run `{sec.commands.get(main, '?')}`.", ""]
            continue
        try:
            lines = sec.build({"results": results, "paper": sec.paper, "name": main})
        except (KeyError, TypeError, AttributeError, ValueError, IndexError) as e:  # a result of another layout
            lines = [f"Could not tabulate these results ({e.__class__.__name__}: {e}); their files are listed below."]
        rows, verdicts = [], []
        for n, p in paths.items():
            if p is None:
                continue
            prov = provenance(results[n])
            verdict, why = staleness(p, prov, sec, git)
            if verdict != "current":
                status[verdict].append(n)
            verdicts.append(verdict)
            note = _checkpoint_note(sec, prov, p, git)
            rows.append([f"`{n}`", f"[{p.name}]({_link(p, out_dir)})", prov["checkpoint"], prov["device"],
                         prov["commit"], prov["date"], f"**{verdict}**: {why}{note}"])
        state = "stale" if "stale" in verdicts else ("unknown" if "unknown" in verdicts else "current")
        state += ", some results missing" if None in paths.values() else ""
        summary.append([f"[{sec.title}](#{key})", tables, state, f"`{sec.commands.get(main, '?')}`"])
        kept = {r: (n, root / p) for r, n, p in sec.records if (root / p).exists()}
        lines += previous_table(key if key in HEADLINES else main, {n: results.get(n) for n, _ in kept.values()},
                                {r: load_json(p) for r, (_, p) in kept.items()}, _EVAL_LABELS)
        for r, (n, p) in kept.items():
            prov = provenance(load_json(p))
            rows.append([f"`{r}`", f"[{p.name}]({_link(p, out_dir)})", prov["checkpoint"], prov["device"],
                         prov["commit"], prov["date"], f"**record** of the models shipped before, beside `{n}`"])
        body += [f'<a id="{key}"></a>', "", head, ""] + lines + [""]
        figs = _figures(sec, results, paths, root)
        if figs:
            body += ["Figures:", ""] + [f"![{f.stem}]({_link(f, out_dir)})" if f.exists()
                                        else f"- missing: `{_link(f, out_dir)}`" for f in figs] + [""]
        body += ["Sources:", ""] + rs.md_table(["result", "file", "checkpoint", "device", "commit", "date",
                                                "up to date?"], rows) + [""]
    at = git.head() if git.available else None
    top = ["# Results report", "",
           f"Written by `volsmpl report` at commit {at or 'unknown (' + (git.reason or 'git unavailable') + ')'}"
           f"{' (with uncommitted changes)' if at and git.dirty(['.']) else ''}. Our numbers beside the "
           "paper's (VolumetricSMPL, ICCV 2025; `volsmpl.report.paper`). The paper measured on GPUs; CPU runs compare "
           "with each other and by ratios. A result is stale when its producer code changed after it was made.",
           ""] + rs.md_table(["section", "paper", "status", "command"], summary) + [""]
    if missing:
        top += ["## Results still missing", ""] + missing + [""]
    return "\n".join(top + body).rstrip() + "\n", status


def _checkpoint_note(sec: Section, prov: dict, path: Path, git: Git) -> str:
    """A note naming the shipped checkpoints that changed after the result (which then describes an earlier one):
    those the result names (by file stem), all of them where it names none of them and says 'shipped' or records
    no checkpoint."""
    if not git.available or not sec.checkpoints:
        return ""
    ck = prov["checkpoint"]
    named = [c for c in sec.checkpoints if Path(c).stem in ck]
    if not named and ("shipped" in ck or ck == "not recorded"):
        named = list(sec.checkpoints)
    commit = prov["commit"] if prov["commit"] != "not recorded" else None
    if not (commit and git.commit_time(commit) is not None):
        rel = _rel_to(path, git.root)
        own = git.last_change([rel]) if rel and not git.dirty([rel]) else None
        commit = own[0] if own else None
    if commit is None:
        return ""
    later = [(c, git.last_change([c], since=commit)) for c in named]
    later = [f"{c} ({x[0]}, {_day(x[1])})" for c, x in later if x]
    return f"; the shipped {', '.join(later)} changed after it: it describes an earlier checkpoint" if later else ""


# -------------------------------------------------------------------------------------------------------------- CLI

def add_parser(sub):
    p = sub.add_parser("report", help="write docs/report.md: every result table beside the paper's numbers",
                       description="Reads the result JSONs of eval, bench, selfpen and the apps (runs no model) and "
                                   "writes a Markdown report with the paper's numbers, figures and provenance.")
    p.add_argument("--out", default=None, help="output Markdown file (default: docs/report.md of the checkout)")
    p.add_argument("--results", nargs="+", default=[], metavar="NAME=PATH",
                   help=f"read result NAME from PATH instead of its default (names: {', '.join(result_names())})")
    p.add_argument("--check", action="store_true", help="exit 1 when a result is stale or missing (for CI)")
    p.add_argument("--verify", nargs="+", default=[], metavar="NAME=PATH",
                   help="compare result NAME with a fresh run of some of its cases (PATH: that run's results.json) "
                        "and store the comparison beside the result (NAME's file .check.json; volsmpl.report.result_check)")
    p.add_argument("--verify-tol", type=float, default=1e-6, help="relative tolerance of --verify (default 1e-6)")
    p.add_argument("--baseline", nargs="+", default=[], metavar="NAME=PATH",
                   help="with --verify NAME=...: compare the fresh run with PATH, a run on the same machine of the code "
                        "of NAME's current agreeing check, instead of with the stored table (another machine's float "
                        "rounding; volsmpl.report.result_check.chain_check)")
    return p


def run(args) -> int:
    overrides = parse_overrides(args.results)
    out = Path(args.out) if args.out else ROOT / "docs" / "report.md"
    check_writable(out, "file", "--out")
    if not (args.verify_tol >= 0):
        raise ValueError(f"--verify-tol must be >= 0, got {args.verify_tol}")
    verify, baselines = (parse_overrides(a, flag=f) for a, f in ((args.verify, "--verify"), (args.baseline, "--baseline")))
    unpaired = sorted(set(baselines) - set(verify))
    if unpaired:
        raise ValueError(f"--baseline {unpaired[0]}=... needs --verify {unpaired[0]}=... (the fresh run to compare with it)")
    for name, fresh in verify.items():
        sec = next(sec for sec in SECTIONS.values() if name in sec.results)
        stored = overrides.get(name) or _locate(sec.results[name], ROOT)
        if stored is None:
            raise ValueError(f"--verify {name}: there is no stored result to compare with; make it first "
                             f"(`{sec.commands.get(name, '?')}`) or give it with --results {name}=PATH")
        c = (chain_check(stored, fresh, baselines[name], rel_tol=args.verify_tol) if name in baselines
             else write_check(stored, fresh, rel_tol=args.verify_tol))
        print(f"{name}: {c['cases_compared']} of {c['cases_total']} cases compared, {c['values_compared']} values, "
              + ("all agree" if c["agree"] else f"{c['n_mismatches']} differ (largest {c['max_abs_diff']:g})")
              + f"; wrote {check_path(stored)}")
    text, status = build_report(out, ROOT, overrides)
    write_atomic(out, text)
    print(f"wrote {out}: " + "; ".join(f"{k}: {', '.join(v) or 'none'}" for k, v in status.items()))
    if args.check and (status["stale"] or status["missing"]):
        return 1
    return 0
