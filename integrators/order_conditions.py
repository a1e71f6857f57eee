"""Classical Runge–Kutta order conditions over rooted trees (Butcher).

A tree is a sorted tuple of its subtrees; the single vertex is ``()``.  The
method (a, b) has order p iff bᵀΦ(t) = 1/γ(t) for every tree with |t| ≤ p,
where Φ_i(t) = Π_k (a Φ(t_k))_i and γ(t) = |t| Π_k γ(t_k).
"""
from __future__ import annotations

import functools

import numpy as np


@functools.lru_cache(maxsize=None)
def trees(order: int) -> tuple:
    """All rooted trees with exactly ``order`` vertices."""
    if order == 1:
        return ((),)
    result = set()
    # a tree of n vertices = root + multiset of subtrees with n − 1 vertices in total
    def partitions(n, max_part):
        if n == 0:
            yield ()
            return
        for k in range(min(n, max_part), 0, -1):
            for rest in partitions(n - k, k):
                yield (k,) + rest
    for parts in partitions(order - 1, order - 1):
        combos = [()]
        for k in parts:
            combos = [c + (t,) for c in combos for t in trees(k)]
        for c in combos:
            result.add(tuple(sorted(c)))
    return tuple(sorted(result))


def size(t) -> int:
    return 1 + sum(size(u) for u in t)


def gamma(t) -> int:
    g = size(t)
    for u in t:
        g *= gamma(u)
    return g


def _phi(t, a):
    out = np.ones(a.shape[0])
    for u in t:
        out = out * (a @ _phi(u, a))
    return out


def order_residuals(a, b, order):
    """max |bᵀΦ(t) − 1/γ(t)| over trees of exactly ``order`` vertices."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    return max(abs(b @ _phi(t, a) - 1.0 / gamma(t)) for t in trees(order))


def order_of(a, b, c=None, max_order=8, tol=1e-12) -> int:
    """Largest p ≤ max_order with every order condition up to p satisfied to ``tol``."""
    p = 0
    for q in range(1, max_order + 1):
        if order_residuals(a, b, q) > tol:
            break
        p = q
    return p
