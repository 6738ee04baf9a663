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
    return float(np.prod(mult + 1.0).real)


def _complex_upper(mult):
    """Multipliers of the complex pairs (upper half plane), away from +1 and -1."""
    return mult[(mult.imag > 1e-6 * np.maximum(1.0, np.abs(mult)))
                & (np.abs(mult - 1.0) > 1e-3) & (np.abs(mult + 1.0) > 1e-3)]


def _ns_test(mult):
    c = _complex_upper(mult)
    out = int(np.sum(np.abs(c) > 1.0))
    near = (np.abs(c[np.argmin(np.abs(np.abs(c) - 1.0))]) - 1.0) if c.size else np.nan
    return c.size, out, near


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
