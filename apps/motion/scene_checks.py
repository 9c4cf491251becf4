"""Checks of a user's scene file (`volsmpl motion --scene`), made right after reading it and before any network
loads: the file itself, its size in metres against a person's, and its up axis.

What cannot be right is refused in one line naming the file and the likely fix (ValueError, or FileNotFoundError
for a missing file); what is merely unusual becomes a warning (`warn(text)`) and a "doubt" that the later refusals
of a start or goal (scenes.check_endpoint, check_pair) repeat as their likely cause. The limits:

    the file: a folder, an empty (0-byte) or unreadable file, a pickled .npy, a format no reader takes -> refused,
        naming the formats read (FORMATS)
    the scene's largest extent (0.5-99.5th percentile of the points per axis, so that a few stray points do not
        count) after --units: > MAX_SPAN_M (2 km) or < MIN_SPAN_M (0.5 m) -> refused, naming the --units that
        brings it nearest a room's size; > LARGE_SPAN_M (200 m) -> warning
    its height along --up < LOW_HEIGHT_M (1.5 m, lower than a person) -> warning
    the up axis (`estimate_floor`): the floor is the axis whose lowest slab holds the most points; when that axis
        is clearly not --up -> refused ("give --up z"), unless --floor-y is given (the user placed the floor:
        warning); when it is unclear and not --up -> warning

The generated rooms (volsmpl.scene, 7.5 x 7.0 m, 2.8 m tall, no ceiling) hold 36% of their points in the floor
slab and at most 15% in a wall's, a score ratio (below) of about 5; a narrow room whose long walls outsize its
floor, or a corridor, comes out unclear (a warning, never a refusal).

    pts = read_points("scan.ply", "--scene", units="mm")   # (N, 3) metres, the file's own axes
    scan = open_scene_file("scan.ply", "--scene", units="mm")   # a Scan read once; scan.overview(n) for the checks
    doubts = check_scene(pts, "scan.ply", up="z", units="mm", floor_y=None, warn=print)
"""
from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
from volsmpl.scene.floor import FLOOR_BAND_M, estimate_floor

__all__ = ["FORMATS", "MAX_SPAN_M", "MIN_SPAN_M", "LARGE_SPAN_M", "LOW_HEIGHT_M", "read_points", "open_scene_file",
           "span", "units_fix", "check_scene"]

FORMATS = ("a mesh or point cloud (ply, obj, off, stl, glb, xyz, ...: what trimesh reads) or an array of x y z "
           "points (.npy, .npz with 'points', .txt, .csv)")
MAX_SPAN_M = 2000.0    # no walkable scene is 2 km across: a file in other units than --units
MIN_SPAN_M = 0.5       # nor smaller than half a metre
LARGE_SPAN_M = 200.0   # larger than a building: unusual
LOW_HEIGHT_M = 1.5     # lower than a person: unusual
AXES = "xyz"
_UNIT_NAMES = {"m": "metres", "cm": "centimetres", "mm": "millimetres"}
ROOM_SIZE_M = 8.0      # a typical room's largest extent: the units fix brings the scene nearest this


def _fail(path, option: str, what: str) -> ValueError:
    return ValueError(f"{option} {path}: {what}; give {FORMATS}")


def _check_file(path, option: str) -> Path:
    """The path of a user's scene file; one line naming the file and the formats read for a missing file, a folder,
    an empty or unreadable file."""
    p = Path(path)
    if p.is_dir():
        raise _fail(path, option, "is a folder, not a file")
    if not p.exists():
        raise FileNotFoundError(f"{option} {path}: no such file; give {FORMATS}")
    if not p.is_file():
        raise _fail(path, option, "is not a regular file")
    if p.stat().st_size == 0:
        raise _fail(path, option, "is empty (0 bytes)")
    if not os.access(p, os.R_OK):
        raise _fail(path, option, "cannot be read (permission denied)")
    return p


def _read(read, path, option: str):
    """read() (a reader of volsmpl.scene.scan) with its errors as one line naming the file (and the formats read
    where no reader takes it)."""
    import zipfile

    try:
        return read()
    except ValueError as e:
        msg = " ".join(str(e).split())
        if msg.startswith(f"{option} "):   # the reader named the file and the fix, or the reader's error
            raise ValueError(msg if "cannot read it (" not in msg else f"{msg}; give {FORMATS}") from None
        raise ValueError(f"{option} {path}: {msg}") from None   # check_cloud: empty, NaN, wrong shape
    except (OSError, EOFError, KeyError, IndexError, UnicodeDecodeError, zipfile.BadZipFile) as e:
        raise _fail(path, option, f"cannot read it ({type(e).__name__}: {' '.join(str(e).split())[:120]})") from None


def read_points(path, option: str = "--scene", units: str = "m", n_surface: int = 65536, seed: int = 0) -> np.ndarray:
    """The points of a user's scene file in metres, in the file's own axes (volsmpl.scene.scan.read_scan), with
    one line naming the file and the formats read for a missing file, a folder, an empty or unreadable file, a
    pickled .npy or a file no reader takes. Shape: -> (N, 3) float64."""
    from volsmpl.scene.scan import read_scan

    p = _check_file(path, option)
    return _read(lambda: read_scan(p, units, n_surface, seed, option=option), path, option)


def open_scene_file(path, option: str = "--scene", units: str = "m"):
    """A user's scene file read once as a volsmpl.scene.scan.Scan (metres, the file's own axes: a mesh keeps its
    triangles, a cloud its points), refused in one line as `read_points` refuses it."""
    from volsmpl.scene.scan import open_scan

    p = _check_file(path, option)
    return _read(lambda: open_scan(p, units, option=option), path, option)


def span(points: np.ndarray) -> np.ndarray:
    """Extent of the points along each axis between their 0.5th and 99.5th percentiles (a few stray points of a
    scan do not count). Shape: (N, 3) -> (3,)."""
    lo, hi = np.percentile(np.asarray(points, dtype=np.float64), [0.5, 99.5], axis=0)
    return hi - lo


def units_fix(extent_m: float, units: str) -> str | None:
    """The --units that brings a scene whose largest extent is `extent_m` metres under `units` nearest a room's
    size (ROOM_SIZE_M) within [MIN_SPAN_M, LARGE_SPAN_M]; None when no unit does (or the given one is best)."""
    from volsmpl.scene.scan import UNITS

    raw = extent_m / UNITS[units]
    fits = {u: raw * f for u, f in UNITS.items() if MIN_SPAN_M <= raw * f <= LARGE_SPAN_M}
    if not fits:
        return None
    best = min(fits, key=lambda u: abs(math.log(fits[u] / ROOM_SIZE_M)))
    return None if best == units else best


def check_scene(points: np.ndarray, path, up: str, units: str, floor_y=None, warn=None,
                option: str = "--scene") -> list[str]:
    """Refuse a scene (points in metres, the file's own axes) whose size cannot be a scene in `units` or whose floor
    clearly lies across another axis than `up` (module docstring); print the floor found; warn about what is
    unusual. Returns the doubts (short reasons the scene looks odd) that later refusals repeat."""
    warn = warn or (lambda text: None)
    name = str(path)
    doubts = []
    ext = span(points)
    big = float(ext.max())
    fix = units_fix(big, units)
    if big > MAX_SPAN_M or big < MIN_SPAN_M:
        size = f"{big:,.0f} m" if big >= 10 else f"{big:.3g} m"
        hint = (f"a scene in {_UNIT_NAMES[fix]}? give --units {fix}" if fix else
                "check the file's units (--units m, cm or mm) or export it in metres")
        limit = f"more than {MAX_SPAN_M:,.0f} m" if big > MAX_SPAN_M else f"less than {MIN_SPAN_M:g} m"
        raise ValueError(f"{option} {name} spans {size} after --units {units}, {limit}: {hint}")
    if big > LARGE_SPAN_M:
        doubts.append(f"it spans {big:,.0f} m after --units {units}"
                      + (f" (in {_UNIT_NAMES[fix]}? --units {fix})" if fix else ""))
        warn(f"{option} {name} spans {big:,.0f} m after --units {units}, larger than a building"
             + (f": if it is in {_UNIT_NAMES[fix]}, give --units {fix}" if fix else ""))
    est = estimate_floor(points)
    print(est.line(), flush=True)
    if est.axis != up:
        told = f"the floor lies across axis {est.axis} ({100 * est.share:.0f}% of the points within " \
               f"{100 * FLOOR_BAND_M:.0f} cm of its level; across {up}: {100 * est.shares[up]:.0f}%)"
        offered = est.axis in ("y", "z")
        if est.clear and floor_y is None:
            fix_up = f"give --up {est.axis}" if offered else "export the scene with y or z up"
            raise ValueError(f"{option} {name}: {told} but --up is {up}: {fix_up} (or --floor-y LEVEL to keep "
                             f"--up {up})")
        doubts.append(f"its floor seems to lie across axis {est.axis}, not --up {up}")
        warn(f"{option} {name}: {told}, not --up {up}"
             + (" (kept: --floor-y given)" if est.clear else "; the up axis is unclear, --up taken as given"))
    height = float(ext[AXES.index(up)])
    if height < LOW_HEIGHT_M:
        doubts.append(f"it is {height:.2f} m tall along --up {up}")
        warn(f"{option} {name} is {height:.2f} m tall along --up {up}, lower than a person: check --up and --units")
    return doubts
