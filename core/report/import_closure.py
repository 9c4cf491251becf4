"""The repository files whose code a result's producer runs: its own modules and every `volsmpl` module they
import, directly or through others (`volsmpl report` calls a result stale when one of them changed after it).

An app's table depends on the core it calls (the body, the volume, the optimiser) as much as on the app's own
files; naming only `apps/<name>` would keep a table current across a core change that alters its numbers. The
imports are read from the source (ast), not by importing: every `import volsmpl...`, `from volsmpl... import`,
and relative import, also those inside functions (lazy imports), and every string naming a module (a registry's
"volsmpl.nn.coap_net:CoapNet", imported by importlib) is followed; a package's `__init__.py` counts
when any of its modules is imported (Python runs it). `volsmpl` maps to `core/` and `volsmpl.apps` to `apps/`
(pyproject's package-dir). The entries themselves are kept as given, so a folder also covers its data files.

    paths = producer_closure(("apps/motion",), root)   # -> ('apps/motion/__init__.py', ..., 'core/volume/learned.py', ...)
"""
from __future__ import annotations

import ast
from functools import lru_cache
from pathlib import Path

#: package prefix -> repository folder (longest prefix first)
PACKAGE_DIRS = (("volsmpl.apps", "apps"), ("volsmpl", "core"))


def module_file(module: str, root: Path) -> Path | None:
    """The source file of a `volsmpl` module (`volsmpl.x.y` -> core/x/y.py or core/x/y/__init__.py), None when
    the module is not one of this repository's."""
    for prefix, folder in PACKAGE_DIRS:
        if module == prefix or module.startswith(prefix + "."):
            rest = module[len(prefix):].lstrip(".").split(".") if module != prefix else []
            base = Path(root, folder, *rest)
            for cand in (base.with_suffix(".py") if rest else None, base / "__init__.py"):
                if cand is not None and cand.is_file():
                    return cand
            return None
    return None


def module_name(path: Path, root: Path) -> str | None:
    """The dotted name of a repository source file (inverse of module_file), None outside core/ and apps/."""
    rel = Path(path).resolve().relative_to(Path(root).resolve())
    for prefix, folder in PACKAGE_DIRS:
        if rel.parts and rel.parts[0] == folder:
            parts = list(rel.with_suffix("").parts[1:])
            if parts and parts[-1] == "__init__":
                parts = parts[:-1]
            return ".".join([prefix, *parts])
    return None


def imported_modules(path: Path, module: str) -> set[str]:
    """Dotted names this file imports (relative imports resolved against `module`); for `from a import b`
    both `a` and `a.b` (b may be a submodule); string constants that name a `volsmpl` module (with or without
    ":attribute") count as imports. Names that are not modules of this repository are dropped later."""
    package = module if Path(path).name == "__init__.py" else module.rpartition(".")[0]
    return set(_imports(Path(path).read_text(encoding="utf-8"), package, str(path)))


@lru_cache(maxsize=1024)
def _imports(text: str, package: str, filename: str) -> frozenset:
    """imported_modules of one source text (memoised by the text itself: a report parses each module once, not
    once per section, and an edited file is parsed again)."""
    tree = ast.parse(text, filename=filename)
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base_parts = package.split(".")
                base_parts = base_parts[:len(base_parts) - (node.level - 1)]
                base = ".".join(base_parts + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            found.add(base)
            found.update(f"{base}.{alias.name}" for alias in node.names if alias.name != "*")
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value.startswith("volsmpl."):
            found.add(node.value.partition(":")[0])  # registry entries import by name: "volsmpl.nn.coap_net:CoapNet"
    return frozenset(found)


def _parents(module: str):
    """volsmpl.a.b -> volsmpl, volsmpl.a (the packages whose __init__ runs first)."""
    parts = module.split(".")
    return [".".join(parts[:i]) for i in range(1, len(parts))]


def producer_closure(entries, root) -> tuple[str, ...]:
    """Repository-relative paths of `entries` (files or folders, relative to root) and of every repository
    module their Python files import, transitively, sorted. Every entry is kept as given (a folder then also
    covers its data files)."""
    rootp = Path(root).resolve()
    kept: set[str] = set()
    todo: list[Path] = []
    for e in entries:
        p = rootp / e
        files = sorted(p.rglob("*.py")) if p.is_dir() else ([p] if p.suffix == ".py" and p.is_file() else [])
        kept.add(e)  # a folder keeps its data files (an app's cases, its network weights)
        todo.extend(f for f in files if module_name(f, rootp) is not None)
    seen: set[Path] = set()
    while todo:
        f = todo.pop()
        if f in seen:
            continue
        seen.add(f)
        name = module_name(f, rootp)
        for mod in imported_modules(f, name) | set(_parents(name)):
            target = module_file(mod, rootp)
            if target is not None and target not in seen:
                todo.append(target)
    kept.update(str(f.relative_to(rootp)) for f in seen)
    return tuple(sorted(kept))


__all__ = ["PACKAGE_DIRS", "imported_modules", "module_file", "module_name", "producer_closure"]
