"""Bifurcation test functions along a branch: folds, period doublings, Neimark–Sacker."""

from __future__ import annotations

import numpy as np


def _pd_test(mult):
    """Product of ``(μ_i + 1)`` (real; changes sign when a real multiplier crosses -1, a
    complex pair contributing ``|μ + 1|² > 0``), also the located quantity: continuous
    where two complex multipliers meet on the negative real axis and part as two real ones,
    one of which then crosses -1 (the real multiplier nearest -1 does not exist on the
    complex side: on the hard rigid scene's 5-impact branch two complex pairs meet near
    21.5 rad/s and the period doubling follows at 21.567 rad/s)."""
    out = 1.0 + 0j
    for m in _values(mult):
        out *= m + 1.0
    return out.real


def _values(mult):
    """The multipliers as Python complex numbers (a few of them: the tests below run at
    every branch point, where numpy's per-call cost on four numbers dominates)."""
    return [complex(m) for m in np.asarray(mult).ravel()]


def _complex_upper(mult):
    """Multipliers of the complex pairs (upper half plane), away from +1 and -1."""
    return [m for m in _values(mult)
            if m.imag > 1e-6 * max(1.0, abs(m)) and abs(m - 1.0) > 1e-3 and abs(m + 1.0) > 1e-3]


def _ns_test(mult):
    c = _complex_upper(mult)
    out = sum(abs(m) > 1.0 for m in c)
    near = min((abs(m) - 1.0 for m in c), key=abs) if c else np.nan
    return len(c), out, near


def _events(a, b):
    """The bifurcation kinds whose test functions change sign between points ``a`` and
    ``b`` (dicts with the tangent ``t`` and multipliers ``mult``)."""
    kinds = []
    if np.sign(a["t"][-1]) * np.sign(b["t"][-1]) < 0:
        kinds.append("fold")
    if np.sign(_pd_test(a["mult"])) * np.sign(_pd_test(b["mult"])) < 0:
        kinds.append("period_doubling")
    ca, oa, _ = _ns_test(a["mult"])
    cb, ob, _ = _ns_test(b["mult"])
    if ca == cb and ca > 0 and oa != ob:
        kinds.append("neimark_sacker")
    return kinds


def _g(kind, point):
    if kind == "fold":
        return float(point["t"][-1])
    if kind == "period_doubling":
        return _pd_test(point["mult"])
    return float(_ns_test(point["mult"])[2])
