"""How a query of B bodies x N points is cut into chunks, and put back together.

A chunk is (b0, b1, s, e): bodies b0 .. b1 - 1, points s .. e - 1. Whole bodies go together while a chunk's
(body, part, point) entries stay within a budget; a body over the budget alone is cut into point ranges.

    chunks = lean_chunks(B=8, N=60000, K=16, budget=1 << 20, step=65536)   # 8 chunks of one body
    values = assemble_chunks([f(c) for c in chunks], chunks, B, N)         # (B, N)
"""
from __future__ import annotations

import torch


def point_ranges(N: int, step: int) -> list:
    """[(s, e), ...] covering 0 .. N in ranges of `step` points (the last shorter)."""
    return [(s, min(N, s + step)) for s in range(0, N, step)]


def lean_chunks(B: int, N: int, K: int, budget: int, step: int) -> list:
    """Chunks (b0, b1, s, e) of a query of B bodies x N points over K parts: as many whole bodies per chunk as
    `budget` entries allow, or, when one body is over it, ranges of `step` points of one body."""
    per_body = K * max(1, N)
    if per_body <= budget:
        nb = max(1, budget // per_body)
        return [(b, min(B, b + nb), 0, N) for b in range(0, B, nb)]
    return [(b, b + 1, s, e) for b in range(B) for s, e in point_ranges(N, step)]


def assemble_chunks(parts: list, chunks: list, B: int, N: int) -> torch.Tensor:
    """Put the (b1 - b0, e - s) results of the chunks (b0, b1, s, e) of a (B, N) query together (differentiably)."""
    rows = []
    i = 0
    while i < len(chunks):
        b0, b1, s, e = chunks[i]
        if s == 0 and e == N:
            rows.append(parts[i])
            i += 1
            continue
        j = i
        while j < len(chunks) and chunks[j][0] == b0:
            j += 1
        rows.append(torch.cat(parts[i:j], dim=1))
        i = j
    return torch.cat(rows, dim=0)
