"""Closed-form reference: the symmetric two-impacts-per-cycle orbit of the impact damper on an
undamped primary (Masri & Caughey).

numpy/scipy only; nothing here imports absorber_jax.

Reference: S. F. Masri, T. K. Caughey, On the stability of the impact damper, Journal of
Applied Mechanics 33 (1966) 586 (the symmetric two-impact orbit and its stability; here
with an undamped primary, where the whole orbit is in closed form).

Scene (the conventions of tests/reference_impacts.py with ``c = 0``)::

    M x1'' + k x1 = F0 sin(W t) + impulses,      m x2'' = -impulses,      |x2 - x1| <= d,

at a wall ``u = x2 - x1 = ±d`` with the ball approaching, the relative velocity
``w = x2' - x1'`` jumps to ``-e w`` and the momentum ``M x1' + m x2'`` is kept.
Write ``w0 = sqrt(k/M)``, ``T = 2 pi / W``, ``mu = m/M``, ``X = F0 / (k - M W^2)`` (the
forced response's signed amplitude, ``x_p(t) = X sin(W t)``) and ``th = w0 T/2 = pi w0/W``.

Orbit sought.  Impacts every half period at alternating walls, with the symmetry
``y(t + T/2) = -y(t)`` of ``y = [x1, v1, x2, v2]`` (the forcing changes sign over ``T/2``
too).  At the impact on the wall ``u = +d`` at time ``t_i`` (forcing phase
``tau = W t_i``) the primary is at ``x0``, its velocity ``v-`` before and ``v+`` after; the
ball leaves with velocity ``V`` and, flying freely, arrives at the other wall ``T/2`` later
with the same velocity ``V``, where by the symmetry the primary is at ``-x0`` with velocities
``-v-`` / ``-v+`` and the ball leaves with ``-V``.  So the ball arrives at ``+d`` with
``-V`` and leaves with ``V``.  Unknowns ``(x0, v-, v+, V, C, S)`` with
``C = X cos tau``, ``S = X sin tau``.  Five equations, all linear:

1. momentum at the impact: ``M v- + m (-V) = M v+ + m V``, i.e. ``v+ - v- = -2 mu V``;
2. restitution: ``V - v+ = -e (-V - v-)``, i.e. ``v+ + e v- = (1 - e) V``;
3. the ball's flight of ``T/2`` from ``x0 + d`` to ``-x0 - d``: ``x0 + d + V T/2 = -x0 - d``,
   i.e. ``V = -4 (x0 + d) / T``;
4. and 5. the exact undamped forced flow of the primary over ``T/2`` from ``(x0, v+)`` at
   ``t_i`` must end at ``(-x0, -v-)``.  After an impact at ``t_i`` the primary moves as
   ``x1(t_i + s) = X sin(tau + W s) + h(s)``, ``h(s) = a cos(w0 s) + (b/w0) sin(w0 s)``,
   ``a = x0 - S``, ``b = v+ - W C`` (note ``X sin(tau + W s) = S cos Ws + C sin Ws``), so with
   ``ct = cos th``, ``st = sin th`` and ``sin(tau + pi) = -sin tau``::

       -x0 = -S + a ct + (b/w0) st      ->   (1 + ct) (x0 - S) + (st/w0) (v+ - W C) = 0
       -v- = -W C - w0 a st + b ct      ->   v- - W C - w0 st (x0 - S) + ct (v+ - W C) = 0

Linear part.  1-3 give ``V``, ``v-``, ``v+`` from ``x0``:
``V = -4 (x0 + d)/T``, ``v- = (1 - e + 2 mu) V/(1 + e)``, ``v+ = (1 - e - 2 e mu) V/(1 + e)``;
4-5 are then a 2x2 system in ``(C, S)`` with determinant ``-2 W (1 + ct)`` (regular unless
``w0/W`` is an odd integer, where the homogeneous flow over ``T/2`` is ``-1`` and the scheme
degenerates: not handled).  Every unknown is therefore affine in ``x0``:
``z = z_p + x0 z_n`` (the particular solution at ``x0 = 0`` plus the null vector of the
5x6 system normalized to ``x0 = 1``).

Closure.  ``C^2 + S^2 = X^2`` is the quadratic
``(C_n^2 + S_n^2) x0^2 + 2 (C_p C_n + S_p S_n) x0 + C_p^2 + S_p^2 - X^2 = 0``: no real root,
or two orbits (a double root at the fold between them), each with ``tau = atan2(S/X, C/X)``.
A root is a physical orbit only if the ball approaches the wall
(``w = -V - v- > 0``) and stays inside the clearance between impacts
(``|u(s)| <= d`` on ``0 < s < T/2``, checked on a fine grid and at the extremes of ``u``,
where ``v1(s) = V``, located by brentq).

Public state at ``t = 0 (mod T)`` (the library's forcing ``F0 sin(W t)``): the impact time
``t_i = tau/W`` mod ``T`` in ``[0, T)``; the last impact at or before ``t = 0`` is
``t_i - j T/2`` with ``j = ceil(t_i/(T/2))`` (an impact at ``t = 0`` itself counts: the
state is the one after it), at the wall ``(-1)^j d``; by the symmetry the
state there after the impact is ``(-1)^j (x0, v+, x0 + d, V)`` and its flight is ``(-1)^j``
times the flight above, so ``y(0) = (-1)^j flight(j T/2 - t_i)`` with
``flight(s) = [x1(t_i + s), v1(t_i + s), x0 + d + V s, V]``.

Amplitude: ``max |x1|`` over a period (= half peak-to-peak by the symmetry), the largest of
``|x0|`` (the impacts) and ``|x1|`` where ``v1 = 0`` inside a flight (sign changes of ``v1``
on a fine grid, located by brentq to rounding).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.optimize import brentq


@dataclasses.dataclass(frozen=True)
class SymmetricOrbit:
    """One symmetric two-impact orbit (see the module's docstring for the symbols)."""

    x0: float           # primary at the impact on the wall u = +d
    v_minus: float      # primary velocity just before that impact
    v_plus: float       # just after
    V: float            # ball velocity leaving the wall u = +d (it arrives with -V)
    C: float            # X cos(tau)
    S: float            # X sin(tau)
    t_impact: float     # the impact time on u = +d in [0, T)
    state: np.ndarray   # public state [x1, v1, x2, v2] at t = 0 (mod T), after an impact there
    amplitude: float    # max |x1| over the period
    approach: float     # approach velocity w = -V - v_minus at that impact
    max_excursion: float  # max |u|/d strictly between impacts
    valid: bool         # approach > 0 and the ball inside the clearance between impacts


class MasriCaughey:
    """Symmetric two-impacts-per-cycle orbits of the undamped impact damper
    ``M x1'' + k x1 = F0 sin(W t)``, ball ``m``, clearance ``|x2 - x1| <= d``, restitution
    ``e``."""

    def __init__(self, M, k, m, gap, e, F0, W):
        self.M, self.k, self.m, self.d, self.e = float(M), float(k), float(m), float(gap), float(e)
        self.F0, self.W = float(F0), float(W)
        self.w0 = np.sqrt(self.k / self.M)
        self.T = 2 * np.pi / self.W
        if self.k == self.M * self.W**2:
            raise ValueError("W at the primary's resonance: no bounded forced response X")
        self.X = self.F0 / (self.k - self.M * self.W**2)
        self.th = np.pi * self.w0 / self.W

    # -- the linear part: each unknown as an affine pair (value at x0 = 0, slope in x0) ----
    def _affine(self):
        d, e, mu, W, w0, T = self.d, self.e, self.m / self.M, self.W, self.w0, self.T
        x0 = np.array([0.0, 1.0])
        V = -4.0 * (x0 + np.array([d, 0.0])) / T
        vm = (1 - e + 2 * mu) * V / (1 + e)
        vp = (1 - e - 2 * e * mu) * V / (1 + e)
        co, si = np.cos(self.th), np.sin(self.th)
        # [[-W si/w0, -(1+co)], [-W (1+co), w0 si]] [C, S] = [r1, r2]
        r1 = -((1 + co) * x0 + si / w0 * vp)
        r2 = -(-w0 * si * x0 + vm + co * vp)
        det = -2 * W * (1 + co)
        if abs(1 + co) < 1e-12:
            raise ValueError("w0/W is an odd integer: the symmetric scheme degenerates")
        C = (w0 * si * r1 + (1 + co) * r2) / det
        S = (-W * si / w0 * r2 + W * (1 + co) * r1) / det
        return x0, vm, vp, V, C, S

    def residuals(self, x0, vm, vp, V, C, S):
        """The five linear equations and the closure, each in its own units (for checks)."""
        M, m, e, W, w0, T = self.M, self.m, self.e, self.W, self.w0, self.T
        co, si = np.cos(self.th), np.sin(self.th)
        return np.array([
            M * (vp - vm) + 2 * m * V,
            vp + e * vm - (1 - e) * V,
            2 * x0 + 2 * self.d + V * T / 2,
            (1 + co) * (x0 - S) + si / w0 * (vp - W * C),
            vm - W * C - w0 * si * (x0 - S) + co * (vp - W * C),
            C**2 + S**2 - self.X**2,
        ])

    # -- the flow of one flight after the impact on u = +d --------------------------------
    def _flight(self, orb, s):
        """``[x1, v1, x2, v2]`` at ``t_impact + s`` (``0 <= s <= T/2``), array in ``s``."""
        s = np.asarray(s, float)
        W, w0 = self.W, self.w0
        a, b = orb["x0"] - orb["S"], orb["vp"] - W * orb["C"]
        cw, sw = np.cos(W * s), np.sin(W * s)
        c0, s0 = np.cos(w0 * s), np.sin(w0 * s)
        x1 = orb["S"] * cw + orb["C"] * sw + a * c0 + b / w0 * s0
        v1 = W * (orb["C"] * cw - orb["S"] * sw) - w0 * a * s0 + b * c0
        x2 = orb["x0"] + self.d + orb["V"] * s
        return np.stack([x1, v1, x2, np.broadcast_to(orb["V"], s.shape)], axis=-1)

    def _roots_of(self, f, lo, hi, n):
        """Zeros of ``f`` on ``(lo, hi)``: sign changes on ``n`` intervals, then brentq."""
        s = np.linspace(lo, hi, n + 1)
        fs = f(s)
        out = []
        for i in range(n):
            if fs[i] == 0.0 and 0 < i:
                out.append(s[i])
            elif fs[i] * fs[i + 1] < 0:
                out.append(brentq(f, s[i], s[i + 1], xtol=1e-15 * (hi - lo), rtol=1e-15,
                                  maxiter=200))
        return out

    def orbits(self, n_grid=4000):
        """The 0 or 2 orbits (tuple of ``SymmetricOrbit``, valid or not; check ``.valid``)."""
        x0, vm, vp, V, C, S = self._affine()
        X = self.X
        qa = C[1] ** 2 + S[1] ** 2
        qb = 2 * (C[0] * C[1] + S[0] * S[1])
        qc = C[0] ** 2 + S[0] ** 2 - X**2
        disc = qb * qb - 4 * qa * qc
        if disc < 0:
            return ()
        q = -0.5 * (qb + np.copysign(np.sqrt(disc), qb))
        roots = sorted([q / qa, qc / q] if q != 0 else [-qb / (2 * qa)] * 2)
        T, W, d = self.T, self.W, self.d
        out = []
        for r in roots:
            orb = {name: float(p[0] + r * p[1]) for name, p in
                   zip(("x0", "vm", "vp", "V", "C", "S"), (x0, vm, vp, V, C, S))}
            tau = np.arctan2(orb["S"] / X, orb["C"] / X)
            t_i = (tau / W) % T
            # the flight containing t = 0 (after the impact if one falls on t = 0)
            j = int(np.ceil(t_i / (T / 2)))
            state = (-1) ** j * self._flight(orb, j * T / 2 - t_i)
            # amplitude: impacts and the turning points of x1 inside the flight
            cands = [abs(orb["x0"])]
            for sr in self._roots_of(lambda s, orb=orb: self._flight(orb, s)[..., 1],
                                     0.0, T / 2, n_grid):
                cands.append(abs(float(self._flight(orb, sr)[0])))
            amp = max(cands)
            # the ball between the walls: a grid and the extremes of u (u' = V - v1 = 0)
            ss = np.linspace(0.0, T / 2, n_grid + 1)[1:-1]
            fl = self._flight(orb, ss)
            exc = np.max(np.abs(fl[:, 2] - fl[:, 0]))
            for sr in self._roots_of(lambda s, orb=orb: orb["V"] - self._flight(orb, s)[..., 1],
                                     0.0, T / 2, n_grid):
                y = self._flight(orb, sr)
                exc = max(exc, abs(float(y[2] - y[0])))
            approach = -orb["V"] - orb["vm"]
            out.append(SymmetricOrbit(
                x0=orb["x0"], v_minus=orb["vm"], v_plus=orb["vp"], V=orb["V"], C=orb["C"],
                S=orb["S"], t_impact=float(t_i), state=np.asarray(state, float),
                amplitude=float(amp), approach=float(approach), max_excursion=float(exc / d),
                valid=bool(approach > 0 and exc <= d * (1 + 1e-12))))
        return tuple(out)

    def trajectory(self, orbit, ts):
        """Public states ``[x1, v1, x2, v2]`` of ``orbit`` (a ``SymmetricOrbit`` of this scene)
        at the times ``ts`` (after the impact at an impact time), from the exact flow of the
        flight each time lies in and the symmetry ``y(t + T/2) = -y(t)``."""
        ts = np.asarray(ts, float)
        half = self.T / 2
        j = np.floor((ts - orbit.t_impact) / half)
        sign = np.where(j % 2 == 0, 1.0, -1.0)
        orb = dict(x0=orbit.x0, vp=orbit.v_plus, V=orbit.V, C=orbit.C, S=orbit.S)
        return sign[..., None] * self._flight(orb, ts - orbit.t_impact - j * half)

    def valid_orbits(self, n_grid=4000):
        return tuple(o for o in self.orbits(n_grid) if o.valid)


def symmetric_orbits(M, k, m, gap, e, F0, W, n_grid=4000):
    """The valid symmetric two-impact orbits (0, 1 or 2) of the undamped impact damper."""
    return MasriCaughey(M, k, m, gap, e, F0, W).valid_orbits(n_grid)
