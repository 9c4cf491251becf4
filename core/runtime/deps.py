"""Heavy optional packages imported on first use, each failure one error that names the fix.

- `MissingDependency`: an ImportError whose message says what needed the package and how to install it; the CLI
  reports it as a user error (one line, exit 2), not as an internal error.
- `open3d_or_none()`: the open3d module, or None where it does not import (callers with a torch path instead).
- `igl_or_none()`: the libigl module (pip package `libigl`, imported as `igl`), or None where it does not import.
- `open3d(purpose)`: the open3d module (BVH distances, ray casts, point-cloud sampling). Its wheel links the system
  library libusb-1.0, which slim images lack: the message then names `apt-get install libusb-1.0-0`.

Example:
    >>> o3d = open3d("the egohmr contact metric")
    >>> scene = o3d.t.geometry.RaycastingScene()
"""
from __future__ import annotations

__all__ = ["MissingDependency", "igl_or_none", "open3d", "open3d_or_none"]


class MissingDependency(ImportError):
    """A package a feature needs does not import; the message names the feature and the fix."""


def open3d_or_none():
    """The open3d module, or None where importing it fails."""
    try:
        import open3d as o3d
    except ImportError:
        return None
    return o3d


def igl_or_none():
    """The libigl module (`igl`), or None where importing it fails."""
    try:
        import igl
    except ImportError:
        return None
    return igl


def open3d(purpose: str):
    """The open3d module, or MissingDependency naming `purpose` and how to install it."""
    try:
        import open3d as o3d
    except ImportError as e:
        hint = ("install the system library: apt-get install libusb-1.0-0" if "libusb" in str(e)
                else "install it: pip install 'open3d>=0.18'")
        raise MissingDependency(f"{purpose} needs open3d, but importing it failed ({e}); {hint}.") from e
    return o3d
