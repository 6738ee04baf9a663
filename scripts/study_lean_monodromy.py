"""Study: how accurate and how cheap is a *structured* monodromy of a modal structure with
nonlinear elements, against the library's forward-mode one?

The library's Floquet monodromy of the 44-state building of ``benchmark_structure.py``
integrates the 44 × 44 sensitivity matrix with Tsit5, steps controlled on the tangents
(``_integration.flow._sensitivity_jacobian``): ~7 s per 64 vmapped orbits, 50× a plain period
integration, and it dominates the sweep.  Its cost is Tsit5's stage arithmetic on the
1980-dimensional augmented state (a trivial tangent rate costs 3.9 of its 5.1 s).

The structured scheme measured here integrates the tangent along the primal's own Tsit5
steps (state-controlled), with the Jacobian split as ``J(t) = A + Ũ(t) Vᵀ``:

- ``A``: the modal block (``q̇ = v``, ``v̇ = -a v - b q`` per mode), propagated exactly by 2 × 2
  exponentials;
- ``Vᵀ``: the rows the elements read (``Φ_u q``, ``Φ_u v``, ``Φ_u M⁻¹K q``, ``Φ_u M⁻¹C v``
  at the elements' DOFs, and the elements' own states): 12 rows for two dampers;
- ``Ũ(t) = (J(t) - A) W``, ``W = pinv(Vᵀ)``: 12 JVPs of the rate per step;
- a step: Strang splitting, ``e^{Ah/2}``, trapezoid on ``ŨVᵀ`` (implicit half by Woodbury,
  a 12 × 12 solve: the stiff friction is A-stable), ``e^{Ah/2}``; 2nd order.
  ``sub`` splits every primal step (Tsit5 dense output), Richardson ``(4 M_2 - M_1) / 3``.

Also a 2-stage Gauss step (order 4) in the interaction picture ``D = e^{Aτ} Y``, where the
rate of ``Y`` keeps rank 12: one 24 × 24 solve per step (``scheme="gauss"``).

Prints, for five orbits of the benchmark sweep, the largest error of the six largest
|multipliers| and of the matrix against a tight reference (forward mode, steps controlled on
the tangents, rtol 1e-9), for the library's Floquet monodromy too, and the time of 64
vmapped monodromies.  Measured on a 2-core machine:

=====================  ==============  ================  ===================
monodromy              |mu| error      matrix error      64 orbits
=====================  ==============  ================  ===================
library (rtol 1e-6)    8e-11 .. 6e-7   8e-5 .. 2e-4      5.3 s (7.2 s)*
strang, sub 1          2e-5 .. 9e-3    9e-3 .. 6e-2      0.95 s
Richardson sub 1 + 2   3e-7 .. 3e-5    3e-4 .. 1e-3      2.9 s
Richardson sub 2 + 4   2e-8 .. 2e-5    1e-5 .. 7e-5      ~5.8 s
gauss, sub 1           2e-7 .. 7e-5    2e-4 .. 9e-4      1.97 s
=====================  ==============  ================  ===================

(* state-controlled / tangent-controlled steps, the library's sensitivity integrations vmapped
in lockstep as the structured schemes are.  The library runs large states' sensitivity
integrations one lane at a time under vmap (``_integration.flow.lane_by_lane``): 1.85 s per 64
monodromies at the linear guesses against 4.31 s in lockstep.)  The structured schemes are
3-5x cheaper but none reaches the library's accuracy at the same cost: their error stops falling at
~1e-5 on the orbits with stick–slip transitions (omega[20], [32], [40]), where the tangent's
rate changes within one of the primal's steps; they need steps controlled on the tangent
(the library's ``tangent_control``) as well.

    python scripts/study_lean_monodromy.py
"""

from __future__ import annotations

import dataclasses
import os
import sys
import time

import diffrax
import jax
import jax.numpy as jnp
import numpy as np

import absorber_jax as aj
from absorber_jax._integration.flow import _scaled_rate, accurate_tangents, make_config
from absorber_jax._periodic.orbit import FLOQUET_RTOL, monodromy

sys.path.insert(0, os.path.dirname(__file__))
from benchmark_structure import F0, scene  # noqa: E402


def _forcing(o):
    return aj.Harmonic(amplitude=F0, omega=o)


def structured_monodromy(system, o, x0, rtol, sub, scheme="strang"):
    st = system.structure
    n, N = st.mass.shape[0], system.num_states
    a = jnp.diag(system.mass_inverse) * jnp.diag(st.damping)
    b = jnp.diag(system.mass_inverse) * jnp.diag(st.stiffness)
    used, _ = system._used()
    Phu = st.dof_map[np.asarray(used)]
    f = _forcing(o)
    s = system.state_scale(f)
    Z = jnp.zeros((len(used), n))
    rows = jnp.concatenate([jnp.concatenate([Phu, Z], 1), jnp.concatenate([Z, Phu], 1),
                            jnp.concatenate([Phu * b, Z], 1), jnp.concatenate([Z, Phu * a], 1)])
    Vt = jnp.concatenate([jnp.concatenate([rows, jnp.zeros((rows.shape[0], N - 2 * n))], 1),
                          jnp.eye(N)[2 * n:]]) * s[None, :]
    W = jnp.linalg.pinv(Vt)
    A = (jnp.zeros((N, N)).at[:n, n:2 * n].set(jnp.eye(n)).at[n:2 * n, :n].set(-jnp.diag(b))
         .at[n:2 * n, n:2 * n].set(-jnp.diag(a)))
    A = A / s[:, None] * s[None, :]
    d = jnp.sqrt((a**2 / 4 - b).astype(complex))

    def half_exp(h):
        # e^{A h} (scaled), as the four diagonals of its 2 x 2 modal blocks
        C = jnp.cosh(d * h).real
        S = (jnp.sinh(d * h) / jnp.where(d == 0, 1, d)).real
        e = jnp.exp(-a * h / 2)
        sq, sv = s[:n], s[n:2 * n]
        return (e * (C + S * a / 2), e * S * sv / sq, -e * S * b * sq / sv, e * (C - S * a / 2))

    def apply(E, D):
        q, v = D[:n], D[n:2 * n]
        return jnp.concatenate([E[0][:, None] * q + E[1][:, None] * v,
                                E[2][:, None] * q + E[3][:, None] * v, D[2 * n:]])

    def apply_t(E, D):
        return apply((E[0], E[2], E[1], E[3]), D)

    def rate(t, x):
        return _scaled_rate((system, f), t, x)

    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(lambda t, x, _: rate(t, x)), diffrax.Tsit5(), 0.0, 2 * jnp.pi / o, None,
        x0, saveat=diffrax.SaveAt(steps=True, dense=sub > 1 or scheme == "gauss"),
        stepsize_controller=diffrax.PIDController(rtol=rtol, atol=rtol), max_steps=4096,
        throw=False)
    ts = jnp.concatenate([jnp.zeros(1), sol.ts])
    ys = jnp.concatenate([x0[None], sol.ys])
    steps = sol.stats["num_accepted_steps"]

    def U(t, x):
        jw = jax.vmap(lambda w: jax.jvp(lambda y: rate(t, y), (x,), (w,))[1], 1, 1)(W)
        return jw - A @ W

    def step(i, D):
        t0, t1 = ts[i], ts[i + 1]

        def part(j, D):
            ta, tb = t0 + (t1 - t0) * j / sub, t0 + (t1 - t0) * (j + 1) / sub
            xa = ys[i] if sub == 1 else jnp.where(j == 0, ys[i], sol.evaluate(ta))
            xb = ys[i + 1] if sub == 1 else jnp.where(j == sub - 1, ys[i + 1], sol.evaluate(tb))
            h = tb - ta
            E = half_exp(h / 2)
            U0, U1 = U(ta, xa), U(tb, xb)
            D = apply(E, D)
            D = D + h / 2 * U0 @ (Vt @ D)
            G = jnp.linalg.solve(jnp.eye(Vt.shape[0]) - h / 2 * Vt @ U1, Vt @ D)
            return apply(E, D + h / 2 * U1 @ G)

        def gauss(j, D):
            # 2-stage Gauss (order 4) on Y = e^{-A(t - ta)} D, whose rate e^{-Aτ} U V^T e^{Aτ}
            # Y keeps rank 12: the stages are G_i = Q_i^T (Y0 + h Σ a_ij P_j G_j), one
            # 24 x 24 solve
            ta = t0 + (t1 - t0) * j / sub
            h = (t1 - t0) / sub
            c = jnp.array([0.5 - 3**0.5 / 6, 0.5 + 3**0.5 / 6])
            ag = jnp.array([[0.25, 0.25 - 3**0.5 / 6], [0.25 + 3**0.5 / 6, 0.25]])
            P, Q = [], []
            for ci in (c[0], c[1]):
                Ui = U(ta + ci * h, sol.evaluate(ta + ci * h))
                P.append(apply(half_exp(-ci * h), Ui))
                Q.append(apply_t(half_exp(ci * h), Vt.T))
            k = Vt.shape[0]
            Mbig = jnp.eye(2 * k) - h * jnp.block(
                [[ag[i, j] * Q[i].T @ P[j] for j in range(2)] for i in range(2)])
            G = jnp.linalg.solve(Mbig, jnp.concatenate([Q[0].T @ D, Q[1].T @ D]))
            Y = D + h * 0.5 * (P[0] @ G[:k] + P[1] @ G[k:])
            return apply(half_exp(h), Y)

        body = gauss if scheme == "gauss" else part
        return jnp.where(i < steps, jax.lax.fori_loop(0, sub, body, D), D)

    return jax.lax.fori_loop(0, steps, step, jnp.eye(N))


def main():
    system, w = scene()
    om = np.linspace(0.7 * w[0], 1.4 * w[0], 64)
    cfg = make_config(system, _forcing(float(om[0])), "tsit5", 1e-7, 1e-7, 200_000)
    lean = jax.jit(lambda o, x, sub, sc="strang":
                   structured_monodromy(system, o, x, 1e-6, sub, sc), static_argnums=(2, 3))
    for i in (5, 20, 32, 40, 60):
        o = float(om[i])
        ss = aj.steady_state(system, _forcing(o), rtol=1e-7, atol=1e-7, root="chord")
        x = jnp.asarray(system.to_internal(ss.state)) / system.state_scale(_forcing(o))
        # the library's fine tier (floquet_matrix computes it where a multiplier lies near
        # the unit circle; elsewhere its coarse tier at FLOQUET_RTOL_COARSE)
        fine = dataclasses.replace(accurate_tangents(cfg), rtol=FLOQUET_RTOL, atol=FLOQUET_RTOL)
        lib = np.asarray(monodromy(system, _forcing(o), x, 1, fine))
        # the reference: forward mode, steps controlled on the tangents, rtol 1e-9
        tight = dataclasses.replace(accurate_tangents(cfg), rtol=1e-9, atol=1e-9)
        ref = np.asarray(monodromy(system, _forcing(o), x, 1, tight))
        M = {"library": lib}
        top = np.sort(np.abs(np.linalg.eigvals(ref)))[::-1][:6]
        M.update({k: np.asarray(lean(o, x, k)) for k in (1, 2, 4)})
        M["R12"] = (4 * M[2] - M[1]) / 3
        M["R24"] = (4 * M[4] - M[2]) / 3
        M["G1"] = np.asarray(lean(o, x, 1, "gauss"))
        for k, m in M.items():
            mu = np.sort(np.abs(np.linalg.eigvals(m)))[::-1][:6]
            print(f"omega[{i}] {k:>7}: |mu| top-6 error {np.abs(mu - top).max():.1e}, "
                  f"matrix error {np.abs(m - ref).max():.1e}")
    X0 = jax.vmap(lambda o: system.linear_guess(_forcing(o)) / system.state_scale(_forcing(o)))(
        jnp.asarray(om))
    for sub, sc in ((1, "strang"), (2, "strang"), (1, "gauss")):
        f = jax.jit(jax.vmap(lambda o, x, sub=sub, sc=sc:
                             structured_monodromy(system, o, x, 1e-6, sub, sc)))
        f(jnp.asarray(om), X0).block_until_ready()
        t = time.perf_counter()
        f(jnp.asarray(om), X0).block_until_ready()
        print(f"64 vmapped structured monodromies, {sc} sub {sub}: "
              f"{time.perf_counter() - t:.2f} s")


if __name__ == "__main__":
    main()
