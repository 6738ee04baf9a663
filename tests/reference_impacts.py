"""Event-exact reference for the rigid impact absorber (Newton's restitution law).

numpy/scipy only; nothing here imports absorber_jax.

Scene: a primary ``M x1'' + c x1' + k x1 = F0 sin(W t) + (impulses)`` carrying a ball ``m``
that flies freely in a clearance ``|x2 - x1| <= d``.  At ``x2 - x1 = ±d`` (approaching) the
relative velocity ``w = x2' - x1'`` jumps to ``-e w`` with momentum conserved
(impulse ``(1+e) m M/(m+M) w``).  A ball pressed against a wall (its free relative
acceleration ``-x1''`` pointing into it) whose remaining Zeno sequence
``2|w+| / (|a| (1-e))`` is shorter than ``zeno`` forcing periods sticks (plastic, momentum
conserved) and moves with the primary (mass ``M + m``) until the wall's force would pull.

Method.  No ODE integrator: between events every motion is known in closed form, the
primary as the forced linear oscillator of mass ``M`` (free flight) or ``M + m`` (stuck),
``x = P sin Wt + Q cos Wt + a1 e^{l1 t} + a2 e^{l2 t}`` (complex roots of ``mu l^2 + c l + k``),
the ball as a straight line.  Impacts are bracketed on a grid of steps no longer than
``1/4000`` of the forcing period, nor a quarter of the flight a constant acceleration would
give after the last impact (so a chattering flight is never stepped over), and located by
brentq (xtol 1e-16); releases likewise on the sign of the holding force.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import brentq


class _Oscillator:
    """Closed-form motion of ``mu x'' + c x' + k x = F0 sin(W t)`` from ``(x0, v0)`` at ``t0``."""

    def __init__(self, mu, c, k, F0, W, t0, x0, v0):
        den = complex(k - mu * W**2, c * W)
        amp = F0 / den                      # x_p = Im(amp e^{iWt})
        self.P, self.Q = amp.real, amp.imag  # x_p = P sin Wt + Q cos Wt
        self.W, self.t0 = W, t0
        disc = np.sqrt(complex(c**2 - 4 * mu * k))
        self.l1, self.l2 = (-c + disc) / (2 * mu), (-c - disc) / (2 * mu)
        xp, vp = self._particular(t0)
        dx, dv = x0 - xp, v0 - vp
        # a1 + a2 = dx, l1 a1 + l2 a2 = dv
        self.a1 = (dv - self.l2 * dx) / (self.l1 - self.l2)
        self.a2 = dx - self.a1

    def _particular(self, t):
        s, co = np.sin(self.W * t), np.cos(self.W * t)
        return self.P * s + self.Q * co, self.W * (self.P * co - self.Q * s)

    def __call__(self, t):
        tau = t - self.t0
        xp, vp = self._particular(t)
        e1, e2 = np.exp(self.l1 * tau), np.exp(self.l2 * tau)
        x = xp + (self.a1 * e1 + self.a2 * e2).real
        v = vp + (self.l1 * self.a1 * e1 + self.l2 * self.a2 * e2).real
        return x, v


def _first_crossing(fns, t0, t1, h, h_max, accept=lambda tr, k: True):
    """The first upcrossing ``(t, k)`` after ``t0`` (before ``t1``) of any of the functions
    ``fns`` that ``accept`` takes, bracketed on steps from ``h`` growing by 1.5 up to
    ``h_max`` and located by brentq; ``None`` when there is none."""
    ta = t0
    while ta < t1:
        tb = min(ta + h, t1)
        found = None
        for k, fn in enumerate(fns):
            if fn(ta) <= 0 < fn(tb):
                tr = brentq(fn, ta, tb, xtol=1e-16, rtol=1e-15, maxiter=500)
                if accept(tr, k) and (found is None or tr < found[0]):
                    found = (tr, k)
        if found is not None:
            return found
        ta, h = tb, min(h_max, h * 1.5)
    return None


def _first_step(T, last_speed, accel):
    """The first bracketing step of a flight: T/4000, at most a quarter of the flight a
    constant acceleration gives after leaving a wall at ``last_speed``."""
    h = T / 4000
    if last_speed is not None:
        h = min(h, 0.25 * 2 * abs(last_speed) / (abs(accel) + 1e-300))
    return max(h, 1e-13)


def _fill(out, ts, t, t_end, to_end, state):
    """``out`` at the samples ``ts`` of the piece from ``t`` to ``t_end`` (inclusive when
    the piece runs ``to_end``) from ``state(t)``."""
    sel = (ts >= t) & ((ts <= t_end) if to_end else (ts < t_end))
    for i in np.nonzero(sel)[0]:
        out[i] = state(ts[i])


class RigidImpactAbsorber:
    def __init__(self, M, k, c, m, gap, e, F0, W, zeno=1e-7):
        self.M, self.k, self.c, self.m, self.d, self.e = M, k, c, m, gap, e
        self.F0, self.W, self.zeno = F0, W, zeno
        self.T = 2 * np.pi / W

    def _force(self, t):
        return self.F0 * np.sin(self.W * t)

    def _free_accel(self, t, x1, v1):
        return (self._force(t) - self.c * v1 - self.k * x1) / self.M

    def _impact(self, t, y, side):
        x1, v1, x2, v2 = y
        w = v2 - v1
        meff = self.M * self.m / (self.M + self.m)
        P = (1 + self.e) * meff * w
        v1n, v2n = v1 + P / self.M, v2 - P / self.m
        x2 = x1 + side * self.d
        a_rel = -self._free_accel(t, x1, v1n)
        w_after = v2n - v1n
        pressed = side * a_rel > 0
        if pressed and self.e < 1:
            tz = 2 * abs(w_after) / (abs(a_rel) * (1 - self.e))
            if tz <= self.zeno * self.T:
                vc = v1 + self.m * w / (self.M + self.m)
                self.losses.append(0.5 * meff * w**2)          # plastic: all of it
                return np.array([x1, vc, x2, vc]), side
        self.losses.append(0.5 * meff * (1 - self.e**2) * w**2)
        return np.array([x1, v1n, x2, v2n]), 0

    def run(self, y0, t0, t1, ts=None):
        """States at ``ts`` (or at ``t1``) from public state ``y0 = [x1, v1, x2, v2]`` at
        ``t0``; returns ``(ys, events)`` with ``events`` a list of ``(t, kind)``,
        ``kind`` in ``{"impact", "stick", "release"}``; the kinetic energy each impact took
        [J] is appended to ``self.losses``."""
        self.losses = []
        y = np.array(y0, float)
        t, mode = t0, 0
        ts = np.array([t1]) if ts is None else np.asarray(ts, float)
        out = np.zeros((len(ts), 4))
        events = []
        last_w = None
        while t < t1:
            if mode == 0:
                osc = _Oscillator(self.M, self.c, self.k, self.F0, self.W, t, y[0], y[1])
                x2_0, v2 = y[2], y[3]

                def state(tq, osc=osc, x2_0=x2_0, v2=v2, t=t):
                    x1, v1 = osc(tq)
                    return np.array([x1, v1, x2_0 + v2 * (tq - t), v2])

                def gfun(tq, side):
                    s = state(tq)
                    return side * (s[2] - s[0]) - self.d

                def approaching(tr, k):
                    # rounding about the wall just after a release (zero relative
                    # velocity, zero acceleration) is no impact
                    sr = state(tr)
                    return (1, -1)[k] * (sr[3] - sr[1]) > 1e-12 * self.d * self.W

                h = _first_step(self.T, last_w, self._free_accel(t, y[0], y[1]))
                found = _first_crossing([lambda tq: gfun(tq, 1), lambda tq: gfun(tq, -1)],
                                        t, t1, h, self.T / 4000, approaching)
                hit = None if found is None else (found[0], (1, -1)[found[1]])
                t_end = hit[0] if hit else t1
                _fill(out, ts, t, t_end, hit is None, state)
                if hit is None:
                    t = t1
                    y = state(t1)
                    break
                t, side = hit
                y, new_mode = self._impact(t, state(t), side)
                events.append((t, "impact"))
                last_w = y[3] - y[1]
                if new_mode:
                    events.append((t, "stick"))
                mode = new_mode
            else:
                side = mode
                osc = _Oscillator(self.M + self.m, self.c, self.k, self.F0, self.W, t, y[0],
                                  y[1])

                def state(tq, osc=osc, side=side):
                    x1, v1 = osc(tq)
                    return np.array([x1, v1, x1 + side * self.d, v1])

                def pull(tq, side=side, osc=osc):
                    x1, v1 = osc(tq)
                    a = (self._force(tq) - self.c * v1 - self.k * x1) / (self.M + self.m)
                    return side * self.m * a

                found = _first_crossing([pull], t, t1, self.T / 4000, self.T / 4000)
                t_rel = None if found is None else found[0]
                t_end = t_rel if t_rel is not None else t1
                _fill(out, ts, t, t_end, t_rel is None, state)
                y = state(t_end)
                t = t_end
                if t_rel is None:
                    break
                events.append((t, "release"))
                mode, last_w = 0, 0.0
        return out, events


class RigidStopOscillator:
    """``m x'' + c x' + k x = F0 sin(W t)`` with a rigid stop at ``x = gap``: at the stop the
    velocity jumps to ``-e`` times itself; pressed against it (the free acceleration pointing
    into it) with a remaining Zeno sequence shorter than ``zeno`` periods, the mass is held
    at the stop until the free acceleration points away.  The same closed-form flights and
    bracketing as ``RigidImpactAbsorber``."""

    def __init__(self, m, c, k, gap, e, F0, W, zeno=1e-7):
        self.m, self.c, self.k, self.d, self.e = m, c, k, gap, e
        self.F0, self.W, self.zeno = F0, W, zeno
        self.T = 2 * np.pi / W

    def _accel(self, t, x, v):
        return (self.F0 * np.sin(self.W * t) - self.c * v - self.k * x) / self.m

    def run(self, y0, t0, t1, ts=None):
        y = np.array(y0, float)
        t, held = t0, False
        ts = np.array([t1]) if ts is None else np.asarray(ts, float)
        out = np.zeros((len(ts), 2))
        events, last_v = [], None
        while t < t1:
            if not held:
                osc = _Oscillator(self.m, self.c, self.k, self.F0, self.W, t, y[0], y[1])

                def g(tq, osc=osc):
                    return osc(tq)[0] - self.d

                h = _first_step(self.T, last_v, self._accel(t, *y))
                found = _first_crossing([g], t, t1, h, self.T / 4000,
                                        lambda tr, k, osc=osc: osc(tr)[1] > 1e-12 * self.d
                                        * self.W)
                hit = None if found is None else found[0]
                t_end = t1 if hit is None else hit
                _fill(out, ts, t, t_end, hit is None, lambda tq, osc=osc: np.array(osc(tq)))
                if hit is None:
                    y, t = np.array(osc(t1)), t1
                    break
                t = hit
                x, v = osc(t)
                v_after = -self.e * v
                a = self._accel(t, self.d, v_after)
                events.append((t, "impact"))
                if a > 0 and self.e < 1 and 2 * abs(v_after) / (a * (1 - self.e)) <= (
                        self.zeno * self.T):
                    y, held = np.array([self.d, 0.0]), True
                    events.append((t, "stick"))
                else:
                    y, last_v = np.array([self.d, v_after]), v_after
            else:
                def push(tq):
                    return -self._accel(tq, self.d, 0.0)

                found = _first_crossing([push], t, t1, self.T / 4000, self.T / 4000)
                t_rel = None if found is None else found[0]
                t_end = t1 if t_rel is None else t_rel
                _fill(out, ts, t, t_end, t_rel is None, lambda tq: np.array([self.d, 0.0]))
                y, t = np.array([self.d, 0.0]), t_end
                if t_rel is None:
                    break
                events.append((t, "release"))
                held, last_v = False, 0.0
        return out, events
