"""Independent event-exact (nonsmooth) reference solutions, written with scipy only.

Nothing here imports absorber_jax: the equations are switched at contact and stick–slip
events and integrated with DOP853 at tight tolerances.
"""

import numpy as np
from scipy.integrate import solve_ivp
from scipy.linalg import expm

RTOL, ATOL = 1e-12, 1e-15


def _collect(sol, t, t_end, t_eval, out_t, out_s):
    """Keep the requested samples that fall in the segment [t, t_end] of a piecewise solve."""
    sel = (t_eval >= t) & (t_eval <= t_end)
    if sel.any():
        out_t.append(t_eval[sel])
        out_s.append(np.atleast_2d(sol.sol(t_eval[sel]).T))


def _assemble(out_t, out_s):
    """(x1, x2) at the requested times, segments joined (a shared end sample kept once)."""
    ts = np.concatenate(out_t)
    ys = np.concatenate(out_s)
    _, idx = np.unique(ts, return_index=True)
    return ys[idx, 0], ys[idx, 2]


def impact_kelvin_voigt(M, k, c, m, d, k1, c1, F0, omega, t_eval, y0=(0, 0, 0, 0),
                        impacts=None):
    """Piecewise-linear impact oscillator: free flight for |y| < d, the Kelvin–Voigt law
    (adhesive, as the paper's) at the wall being penetrated.  Returns x1, x2 at t_eval; the
    times a wall is hit (located events) are appended to the list ``impacts`` if given."""

    def rhs(mode):
        def f(t, s):
            x1, v1, x2, v2 = s
            y, yd = x2 - x1, v2 - v1
            if mode == 1:
                fc = k1 * (y - d) + c1 * yd
            elif mode == -1:
                fc = k1 * (y + d) + c1 * yd
            else:
                fc = 0.0
            a1 = (F0 * np.sin(omega * t) - c * v1 - k * x1 + fc) / M
            return [v1, a1, v2, -fc / m]

        return f

    def event(sign, direction):
        def g(t, s):
            return (s[2] - s[0]) - sign * d

        g.terminal, g.direction = True, direction
        return g

    # watched crossings per mode; the direction keeps a restart on the wall from re-firing
    events = {0: [event(1, 1), event(-1, -1)], 1: [event(1, -1)], -1: [event(-1, 1)]}
    t, s = 0.0, np.array(y0, dtype=float)
    y = s[2] - s[0]
    mode = 1 if y > d else (-1 if y < -d else 0)
    t1 = t_eval[-1]
    out_t, out_s = [], []
    while t < t1:
        sol = solve_ivp(rhs(mode), (t, t1), s, method="DOP853", rtol=RTOL, atol=ATOL,
                        events=events[mode], dense_output=True)
        t_end = sol.t[-1]
        _collect(sol, t, t_end, t_eval, out_t, out_s)
        if sol.status != 1:
            break
        s = sol.y[:, -1].copy()
        if mode != 0:
            mode = 0  # left the wall
        else:
            mode = 1 if sol.t_events[0].size else -1  # hit the right / left wall
            if impacts is not None:
                impacts.append(t_end)
        t = t_end
    return _assemble(out_t, out_s)


def friction_coulomb(m1, k1, c1, m2, k2, c2, mu, N, F0, omega, t_eval):
    """Event-exact Coulomb stick–slip (static = kinetic coefficient ``mu``), from rest."""
    return friction_stick_slip(m1, k1, c1, m2, k2, c2, mu, mu, np.inf, N, F0, omega, t_eval)


def friction_stick_slip(m1, k1, c1, m2, k2, c2, mu_c, mu_s, v_s, N, F0, omega, t_eval):
    """Event-exact stick–slip with a Stribeck friction curve, from rest.

    Modes: stick (the masses move together, X frozen) while the friction needed to hold them
    stays within mu_s N; slip with Fnl = ±N (mu_c + (mu_s - mu_c) exp(-(V/v_s)^2)) until the
    relative velocity V returns to zero (v_s = inf: Coulomb with mu_c = mu_s)."""
    model = StickSlip(m1, k1, c1, m2, k2, c2, mu_c, mu_s, v_s, N, F0, omega)
    out_t, out_s = [], []
    model.run(np.zeros(4), 0, 0.0, t_eval[-1], t_eval, out_t, out_s)
    return _assemble(out_t, out_s)


class StickSlip:
    """The event-switched stick–slip equations (see ``friction_stick_slip``), run from
    any state and mode: ``run`` returns the state and mode at ``t1``."""

    def __init__(self, m1, k1, c1, m2, k2, c2, mu_c, mu_s, v_s, N, F0, omega, rtol=RTOL,
                 atol=ATOL):
        self.p = (m1, k1, c1, m2, k2, c2, mu_c, mu_s, v_s, N, F0, omega)
        self.fmax, self.rtol, self.atol = mu_s * N, rtol, atol

    def f_required(self, t, s):
        m1, k1, c1, m2, k2, c2, *_, F0, omega = self.p
        x1, v1, x2, v2 = s
        a = (F0 * np.sin(omega * t) - c1 * v1 - k1 * x1) / (m1 + m2)
        return m2 * a - k2 * (x1 - x2) - c2 * (v1 - v2)

    def rhs(self, mode):
        m1, k1, c1, m2, k2, c2, mu_c, mu_s, v_s, N, F0, omega = self.p

        def f(t, s):
            x1, v1, x2, v2 = s
            if mode == 0:
                a = (F0 * np.sin(omega * t) - c1 * v1 - k1 * x1) / (m1 + m2)
                return [v1, a, v2, a]
            X, V = x1 - x2, v1 - v2
            fnl = mode * N * (mu_c + (mu_s - mu_c) * np.exp(-((V / v_s) ** 2)))
            a1 = (F0 * np.sin(omega * t) - c1 * v1 - k1 * x1 - c2 * V - k2 * X - fnl) / m1
            a2 = (c2 * V + k2 * X + fnl) / m2
            return [v1, a1, v2, a2]

        return f

    def events(self, mode):
        if mode == 0:
            def g(t, s):
                return abs(self.f_required(t, s)) - self.fmax

            g.terminal, g.direction = True, 1
            return [g]

        def v(t, s):
            return s[1] - s[3]

        v.terminal, v.direction = True, -mode
        return [v]

    def run(self, s, mode, t, t1, t_eval=None, out_t=None, out_s=None):
        s = np.array(s, dtype=float)
        nudge = False
        while t < t1:
            if nudge:  # a grazing transition fired at once: step 1e-10 s in the new mode
                s = solve_ivp(self.rhs(mode), (t, t + 1e-10), s, method="DOP853",
                              rtol=self.rtol, atol=self.atol).y[:, -1]
                t += 1e-10
            sol = solve_ivp(self.rhs(mode), (t, t1), s, method="DOP853", rtol=self.rtol,
                            atol=self.atol, events=self.events(mode),
                            dense_output=t_eval is not None)
            nudge = sol.t[-1] - t < 1e-12
            t_end = sol.t[-1]
            if t_eval is not None:
                _collect(sol, t, t_end, t_eval, out_t, out_s)
            s = sol.y[:, -1].copy()
            if sol.status != 1:
                break
            fr = self.f_required(t_end, s)
            if mode == 0:
                mode = 1 if fr > 0 else -1
            else:
                s[3] = s[1]  # exactly zero relative velocity
                mode = 0 if abs(fr) <= self.fmax else (1 if fr > 0 else -1)
            t = t_end
        return s, mode


def den_hartog_amplitude(m, k, F, P, omega):
    """Exact amplitude of m x'' + k x + F sign(x') = P sin(ωt + φ) with continuous sliding,
    built as Den Hartog (1930) did: on the half period with x' > 0 the motion is linear; its
    ends are turning points at -X and +X (symmetry)."""
    from scipy.optimize import fsolve

    wn = np.sqrt(k / m)
    Tn = np.pi / omega

    def residual(p):
        X, phi = p
        a = P / (k - m * omega**2)
        # x = A cos(wn t) + B sin(wn t) + a sin(ωt + φ) - F/k, x(0) = -X, x'(0) = 0
        A = -X - a * np.sin(phi) + F / k
        B = -a * omega * np.cos(phi) / wn
        x = A * np.cos(wn * Tn) + B * np.sin(wn * Tn) + a * np.sin(omega * Tn + phi) - F / k
        v = (-A * wn * np.sin(wn * Tn) + B * wn * np.cos(wn * Tn)
             + a * omega * np.cos(omega * Tn + phi))
        return [x - X, v]

    X0 = P / abs(k - m * omega**2)
    X, phi = fsolve(residual, [X0, -np.pi / 2], xtol=1e-14)
    return abs(X)


def linear_two_mass(Mmat, Cmat, Kmat, fvec, F0, omega, t_eval):
    """Exact response from rest of M q'' + C q' + K q = f F0 sin(ωt): particular harmonic
    solution plus the matrix-exponential homogeneous part."""
    n = Mmat.shape[0]
    Minv = np.linalg.inv(Mmat)
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-Minv @ Kmat, -Minv @ Cmat]])
    b = np.concatenate([np.zeros(n), Minv @ fvec]) * F0
    Y = np.linalg.solve(1j * omega * np.eye(2 * n) - A, b)  # response to b e^{iωt}
    yp = lambda t: np.imag(Y * np.exp(1j * omega * t))
    h0 = -yp(0.0)
    return np.array([expm(A * t) @ h0 + yp(t) for t in t_eval])
