"""Study: does propagating the modal block exactly reduce the steps per period on the 20-DOF
building of ``scripts/benchmark_structure.py``?

Adaptive Tsit5 at rtol 1e-7 takes ~600 steps per period there, and the high modes set that
count: 604 with 20 modes, 291 with 5; with the error norm restricted to modes 1-5 and the
dampers, ~300 steps and the low modes as accurate.  An exponential
integrator (``y' = L y + N(t, y)``, ``L`` the modal block, propagated exactly) would not
resolve the high modes' own oscillation.  This study compares, at *fixed* steps over one
period from three orbits of the sweep, ETDRK4 (Cox & Matthews 2002, 4 evaluations of ``N``
per step, the phi-functions of each 2 x 2 modal block by the augmented-matrix exponential)
with fixed-step Tsit5 and Dopri5, errors against Dopri8 at rtol 1e-12 (scaled max-norm).

Measured (orbits at 0.865 / 0.975 / 1.139 ω1):

    steps   ETDRK4                Tsit5                 Dopri5
    150     2.4e-1 3.9e-1 1.3e-1  1.2e+0 3.6e-1 2.8e-1  1.2e+0 2.9e-1 2.1e-1
    300     9.6e-2 4.2e-2 2.0e-2  1.7e-1 8.9e-3 1.2e-2  5.8e-2 9.9e-3 1.5e-2
    600     2.3e-3 1.2e-2 2.4e-4  1.5e-3 9.5e-2 3.6e-4  2.6e-3 4.7e-2 8.3e-5
    1200    6.3e-4 1.7e-3 3.6e-5  1.4e-4 4.4e-3 1.3e-5  1.3e-4 3.3e-3 3.3e-6

With fixed steps no method is near the ~1e-6 that adaptive Tsit5 reaches in 600 steps, and
ETDRK4 has no edge: the error is made at the dampers' stick–slip transitions, which adaptive
steps resolve locally.  Whether an *adaptive* exponential integrator (an embedded pair, not
tried here) saves the ~300 steps the high modes cost away from those transitions is the
open question.

    python scripts/study_exponential.py
"""
import os
import sys

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import scipy.linalg as sl

sys.path.insert(0, os.path.dirname(__file__))
from benchmark_structure import F0, RTOL, scene  # noqa: E402

import absorber_jax as aj  # noqa: E402
from absorber_jax._integration.flow import state_scale  # noqa: E402

PICK = (60, 100, 160)           # of the benchmark's 256-frequency grid
STEPS = (150, 300, 600, 1200)


def modal_phis(system, h, kmax=3):
    """phi_0 .. phi_kmax of ``h L_j`` for every 2 x 2 modal block ``L_j`` (shape
    ``(kmax + 1, n, 2, 2)``), from the exponential of the augmented block matrix."""
    n = system.num_coords
    st = system.structure
    kd, cd = np.diag(np.asarray(st.stiffness)), np.diag(np.asarray(st.damping))
    mi = np.diag(np.asarray(system.mass_inverse))
    out = np.zeros((kmax + 1, n, 2, 2))
    for j in range(n):
        big = np.zeros((2 * (kmax + 1), 2 * (kmax + 1)))
        big[:2, :2] = h * np.array([[0.0, 1.0], [-mi[j] * kd[j], -mi[j] * cd[j]]])
        for k in range(kmax):
            big[2 * k:2 * k + 2, 2 * k + 2:2 * k + 4] = np.eye(2)
        e = sl.expm(big)
        out[0, j] = e[:2, :2]
        for k in range(1, kmax + 1):
            out[k, j] = e[:2, 2 * k:2 * k + 2]
    return out


def etdrk4_period(system, forcing, y0, nsteps):
    """One forcing period by ETDRK4 at ``nsteps`` fixed steps (internal state): the modal
    block propagated exactly, the element states (``L = 0``) by the scheme's RK4 limit."""
    n = system.num_coords
    st = system.structure
    kd, cd = np.diag(np.asarray(st.stiffness)), np.diag(np.asarray(st.damping))
    mi = np.diag(np.asarray(system.mass_inverse))
    vf = jax.jit(lambda t, y: system.vector_field(t, y, forcing))

    def nonlinear(t, y):
        lin = np.concatenate([y[n:2 * n], -mi * (kd * y[:n] + cd * y[n:2 * n]),
                              np.zeros(y.size - 2 * n)])
        return np.asarray(vf(t, y)) - lin

    period = 2 * np.pi / float(forcing.omega)
    h = period / nsteps
    full, half = modal_phis(system, h), modal_phis(system, h / 2)
    scalar = {0: 1.0, 1: 1.0, 2: 0.5, 3: 1.0 / 6.0}        # phi_k(0)

    def phi(ph, k, v):
        pairs = np.einsum("jab,jb->ja", ph[k], np.stack([v[:n], v[n:2 * n]], axis=1))
        return np.concatenate([pairs[:, 0], pairs[:, 1], v[2 * n:] * scalar[k]])

    y, t = np.asarray(y0, dtype=float).copy(), 0.0
    for _ in range(nsteps):
        nu = nonlinear(t, y)
        a = phi(half, 0, y) + h / 2 * phi(half, 1, nu)
        na = nonlinear(t + h / 2, a)
        b = phi(half, 0, y) + h / 2 * phi(half, 1, na)
        nb = nonlinear(t + h / 2, b)
        c = phi(half, 0, a) + h / 2 * phi(half, 1, 2 * nb - nu)
        nc = nonlinear(t + h, c)
        y = phi(full, 0, y) + h * (phi(full, 1, nu) - 3 * phi(full, 2, nu)
                                   + 4 * phi(full, 3, nu)
                                   + 2 * (phi(full, 2, na + nb) - 2 * phi(full, 3, na + nb))
                                   + 4 * phi(full, 3, nc) - phi(full, 2, nc))
        t += h
    return y


def diffrax_period(system, forcing, y0, solver, nsteps=None):
    """One forcing period by ``solver`` at ``nsteps`` fixed steps (None: adaptive, rtol
    1e-12 on the scaled state)."""
    period = 2 * np.pi / float(forcing.omega)
    term = diffrax.ODETerm(lambda t, y, a: system.vector_field(t, y, forcing))
    if nsteps is None:
        ctrl = diffrax.PIDController(rtol=1e-12,
                                     atol=1e-12 * np.asarray(state_scale(system, forcing)))
        dt0 = None
    else:
        ctrl, dt0 = diffrax.ConstantStepSize(), period / nsteps
    sol = diffrax.diffeqsolve(term, solver, 0.0, period, dt0, jnp.asarray(y0),
                              stepsize_controller=ctrl, max_steps=200_000)
    return np.asarray(sol.ys[-1])


def main():
    system, w = scene()
    grid = np.linspace(0.7 * w[0], 1.4 * w[0], 256)
    oms = grid[list(PICK)]
    fr = aj.frequency_response(system, oms, amplitude=F0, rtol=RTOL, atol=RTOL,
                               root="newton", floquet=False)
    for om, y0 in zip(oms, np.asarray(fr.states)):
        forcing = aj.Harmonic(amplitude=F0, omega=float(om))
        scale = np.asarray(state_scale(system, forcing))
        ref = diffrax_period(system, forcing, y0, diffrax.Dopri8())
        for ns in STEPS:
            errs = [np.max(np.abs(y - ref) / scale) for y in (
                etdrk4_period(system, forcing, y0, ns),
                diffrax_period(system, forcing, y0, diffrax.Tsit5(), ns),
                diffrax_period(system, forcing, y0, diffrax.Dopri5(), ns))]
            print(f"{om / w[0]:.3f} w1, {ns:5d} steps: ETDRK4 {errs[0]:.1e}  Tsit5 {errs[1]:.1e}"
                  f"  Dopri5 {errs[2]:.1e}", flush=True)


if __name__ == "__main__":
    main()
