"""Output paths of the subcommands: check them before the job runs, write results atomically.

    check_writable(args.out, kind="dir", option="--out")   # at the start of run(args): fails in one clear line
    ...                                                    # the (long) job
    write_atomic(Path(args.out) / "results.json", text)    # a temp file + os.replace: never a half-written file
    with exclusive_folder(out_dir, "volsmpl train"): ...   # a second writer of the folder stops in one line

check_writable creates the missing parent folders (and, for kind='dir', the folder itself) and proves the
place writable by creating and removing a temporary file there, so a read-only folder, a path through a
file, or a file where a folder is expected (and the reverse) is found in seconds instead of after the job.
Its errors are ValueError (the CLI prints them as one line, exit 2).
"""
from __future__ import annotations

import contextlib
import hashlib
import os
import tempfile
from pathlib import Path

__all__ = ["check_writable", "exclusive_folder", "write_atomic", "file_sha256"]


def _probe(folder: Path) -> None:
    """Create and remove a temporary file in `folder` (OSError if that cannot be done)."""
    fd, tmp = tempfile.mkstemp(prefix=".volsmpl_write_check.", dir=folder)
    os.close(fd)
    os.unlink(tmp)


def _reason(e: OSError) -> str:
    return e.strerror or type(e).__name__


def check_writable(path, kind: str = "file", option: str = "--out") -> Path:
    """Check that `path` can be written as a `kind` ('file' or 'dir') before any work; return it as a Path.

    Creates the parent folders (kind='file') or the folder itself (kind='dir'). An existing file is
    overwritten later (kind='file'); an existing folder is written into (kind='dir').
    Raises ValueError naming `option`, the path, the problem and the fix.
    """
    if kind not in ("file", "dir"):
        raise ValueError(f"check_writable: kind must be 'file' or 'dir', got {kind!r}")
    p = Path(path).expanduser()
    what = f"{option} {path}"
    if str(path).strip() == "":
        raise ValueError(f"{option} is empty: give a {'file path' if kind == 'file' else 'folder'}.")
    if kind == "file":
        if p.is_dir():
            raise ValueError(f"{what} is an existing folder; give a file path (e.g. {p / 'results.json'}).")
        if p.exists() and not p.is_file():
            raise ValueError(f"{what} exists and is not a regular file; give a file path.")
        folder = p.parent
    else:
        if p.exists() and not p.is_dir():
            raise ValueError(f"{what} is an existing file, but a folder is expected; give a folder path "
                             f"(e.g. {p.with_suffix('')}_out).")
        folder = p
    # the nearest existing ancestor must be a folder (a path through a file can never be written)
    anc = folder
    while not anc.exists() and anc != anc.parent:
        anc = anc.parent
    if anc.exists() and not anc.is_dir():
        raise ValueError(f"{what}: {anc} is a file, so nothing can be written below it; give a path in a folder.")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise ValueError(f"{what}: cannot create the folder {folder} ({_reason(e)}); "
                         f"give a path in a writable folder.") from None
    try:
        _probe(folder)
    except OSError as e:
        raise ValueError(f"{what}: cannot write in {folder} ({_reason(e)}); give a path in a writable folder.") from None
    return p


def write_atomic(path, data) -> None:
    """Write `data` (str, UTF-8, or bytes) to `path` through a temporary file in the same folder and
    os.replace: readers see the old file or the new one, never a partial write. Creates parent folders."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data.encode("utf-8") if isinstance(data, str) else bytes(data))
        try:  # mkstemp makes the file 0600: keep the old file's mode, else the usual 0644
            os.chmod(tmp, path.stat().st_mode & 0o7777 if path.exists() else 0o644)
        except OSError:
            pass
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


@contextlib.contextmanager
def exclusive_folder(folder, who: str):
    """Hold an exclusive lock on `folder` (created if missing) for the block: a second process asking for it gets
    a RuntimeError in one line naming the holder's pid. The lock (flock on folder/.lock) is released when the block
    ends and by the system when the holder dies, even by SIGKILL, so a killed run never leaves a stale lock."""
    import fcntl

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    fh = open(folder / ".lock", "a+")
    try:
        try:
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            fh.seek(0)
            holder = fh.read().strip() or "?"
            raise RuntimeError(f"{folder} is being written by another {who} (pid {holder}); wait for it to end or "
                               f"choose another output folder.") from None
        fh.seek(0)
        fh.truncate()
        fh.write(str(os.getpid()))
        fh.flush()
        yield folder
    finally:
        fh.close()  # closing releases the lock


def file_sha256(path) -> str:
    """'sha256:<hex>' of a file's bytes (read in 1 MiB blocks)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return "sha256:" + h.hexdigest()
