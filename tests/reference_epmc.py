"""Independent reference: damped nonlinear modes (extended periodic motion concept) by
shooting with scipy; nothing here imports absorber_jax.

System (NLvib example 05, after Laxalde & Thouverez 2009): a 2-DOF chain with tanh-smoothed
dry friction at its first degree of freedom, free vibration with the artificial damping
``-ξ M q̇``:

    M q'' + (C - ξ M) q' + K q + f(q1') e1 = 0,   M = diag(0.02, 1),  C = 0,
    K = [[40, -40], [-40, 640]],                  f = 5 tanh(q1' / 0.05).

Unknowns ``(q1(0), q2(0), q1'(0), ω, ξ)``, ``q2'(0) = 0`` (phase); equations: the state after
one period ``T = 2π/ω`` equals the start (four), and the modal amplitude ``a``:
``Σ_k ψ_kᴴ M ψ_k a² = 2 <qᵀMq> - <q>ᵀM<q>`` (Parseval; ``< >`` the mean over a period),
integrated with the state.  LSODA (stiff/non-stiff switching) at rtol 1e-12 with the exact
Jacobian (the friction's velocity scale makes the first degree of freedom stiff: c/m = 5000
1/s against ω ≈ 25 rad/s): its end state agrees with Radau's at rtol 1e-12 to ~1e-12, in
about a thirtieth of the time."""

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import fsolve

M = np.diag([0.02, 1.0])
K = np.array([[40.0, -40.0], [-40.0, 640.0]])
MU_N, EPS = 5.0, 0.05


def _rhs(xi):
    Minv = np.linalg.inv(M)

    def f(t, y):
        q, v = y[:2], y[2:4]
        force = K @ q - xi * (M @ v) + np.array([MU_N * np.tanh(v[0] / EPS), 0.0])
        acc = -Minv @ force
        return np.concatenate([v, acc, q, [q @ M @ q]])

    def jac(t, y):
        q, v = y[:2], y[2:4]
        J = np.zeros((7, 7))
        J[0:2, 2:4] = np.eye(2)
        dv = -xi * M + np.diag([MU_N / EPS / np.cosh(v[0] / EPS) ** 2, 0.0])
        J[2:4, 0:2] = -Minv @ K
        J[2:4, 2:4] = -Minv @ dv
        J[4:6, 0:2] = np.eye(2)
        J[6, 0:2] = 2 * (M @ q)
        return J

    return f, jac


def _period(u):
    q1, q2, v1, w, xi = u
    y0 = np.array([q1, q2, v1, 0.0, 0.0, 0.0, 0.0])
    T = 2 * np.pi / w
    f, jac = _rhs(xi)
    sol = solve_ivp(f, (0.0, T), y0, method="LSODA", jac=jac, rtol=1e-12, atol=1e-14)
    yT = sol.y[:, -1]
    mean_q, mean_e = yT[4:6] / T, yT[6] / T
    return yT[:4] - y0[:4], 2 * mean_e - mean_q @ M @ mean_q


def damped_mode(a, guess):
    """``(ω [rad/s], ζ, (q1, q2, q1') at t = 0)`` of the mode at modal amplitude ``a`` from
    ``guess`` ``(q1, q2, q1', ω, ξ)``; the residual is checked below 1e-9."""
    def residual(u):
        d, e = _period(u)
        return np.concatenate([d, [e / a**2 - 1.0]])

    u, _, ier, msg = fsolve(residual, guess, full_output=True, xtol=1e-13)
    r = np.max(np.abs(residual(u)))
    if ier != 1 or r > 1e-9:
        raise RuntimeError(f"reference shooting did not converge ({msg}, residual {r:.2g})")
    return u[3], u[4] / (2 * u[3]), u[:3]
