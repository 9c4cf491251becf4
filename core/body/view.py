"""A one-body view of a batched body output, for any volume query.

    sub = select_body(out, 2)            # body 2 of out, as a batch of 1
    sdf = body.volume.query(sub, points) # (1, N)
"""
from __future__ import annotations

__all__ = ["select_body"]


class _OneBody:
    """Body b of a batched output, with the fields a Volume reads."""

    def __init__(self, out, b: int):
        for name in ("vertices", "joints", "full_pose"):
            setattr(self, name, getattr(out, name)[b:b + 1])


def select_body(out, b: int):
    """A one-body view (batch of 1) of body b of a batched body output, for any volume query."""
    return _OneBody(out, b)
