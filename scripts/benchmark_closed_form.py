"""Benchmark: closed-form flights (the matrix exponential between rigid impacts) against
diffrax's event-driven solve (Tsit5, rtol = atol = 1e-9, the periodic solvers' default),
side by side in one run, on the hard impact absorber (M = 1 kg, k = 1e3 N/m, c = 0.5 N s/m,
m = 0.2 kg, gap 2 mm, e = 0.6, F0 = 3 N at 30 rad/s) over one forcing period: the period
map, its Jacobian in the state and the frequency (shooting's and continuation's Newton
matrix), and that Jacobian with 256 samples (an orbit's statistics differentiated).  Each
timing is the mean of 30 compiled calls; the errors are against diffrax at rtol = atol =
1e-13 (its forward-mode Jacobian for the Jacobian).

    python scripts/benchmark_closed_form.py
"""

from __future__ import annotations

import time

import jax
import jax.numpy as jnp
import numpy as np

import absorber_jax as aj
from absorber_jax._integration.flow import integrate_flow, make_config, state_scale

SYSTEM = aj.ImpactAbsorber(M=1.0, k=1e3, c=0.5, m=0.2, gap=2e-3, contact=aj.Restitution(0.6))
X0 = jnp.array([0.01, 0.0, 0.0, 0.3])           # [m, m/s]: x1, v1, x2, v2
SCALE = state_scale(SYSTEM, aj.Harmonic(amplitude=3.0, omega=30.0))


def period_end(solver, rtol, samples):
    def run(x0, w):
        f = aj.Harmonic(amplitude=3.0, omega=w)
        ts = None if samples is None else f.period * jnp.arange(samples) / samples
        cfg = make_config(SYSTEM, f, solver=solver, rtol=rtol, atol=rtol)
        ys, _ = integrate_flow((SYSTEM, f), SYSTEM.to_internal(x0) / SCALE, f.period, ts,
                               cfg=cfg)
        return ys * SCALE

    return run


def timed(fn, *args, reps=30):
    jax.block_until_ready(fn(*args))
    t0 = time.perf_counter()
    for _ in range(reps):
        out = fn(*args)
    jax.block_until_ready(out)
    return (time.perf_counter() - t0) / reps, out


def main():
    ref = jax.jit(period_end("tsit5", 1e-13, None))(X0, 30.0)[-1]
    ref_jac = jax.jit(jax.jacfwd(period_end("tsit5", 1e-13, None), argnums=(0, 1)))(X0, 30.0)
    ref_jac = np.column_stack([np.asarray(ref_jac[0])[-1], np.asarray(ref_jac[1])[-1]])
    cases = (("period map", None, False),
             ("Jacobian (state, omega) of the period map", None, True),
             ("Jacobian (state, omega), 256 samples", 256, True))
    for what, samples, jac in cases:
        times = {}
        for name, solver in (("closed form", None), ("diffrax Tsit5", "tsit5")):
            run = period_end(solver, 1e-9, samples)
            fn = jax.jit(jax.jacfwd(run, argnums=(0, 1))) if jac else jax.jit(run)
            times[name], out = timed(fn, X0, 30.0)
            extra = ""
            if samples is None and not jac:
                extra = (f", error {float(jnp.max(jnp.abs(out[-1] - ref) / SCALE)):.1e} of the "
                         "state scale against diffrax at 1e-13")
            elif samples is None:
                J = np.column_stack([np.asarray(out[0])[-1], np.asarray(out[1])[-1]])
                diff = np.max(np.abs(J - ref_jac)) / np.max(np.abs(ref_jac))
                extra = (f", largest difference {diff:.1e} of the largest entry from "
                         "diffrax's at 1e-13")
            print(f"{what}: {name} {times[name] * 1e3:.3f} ms{extra}", flush=True)
        print(f"{what}: diffrax / closed form = "
              f"{times['diffrax Tsit5'] / times['closed form']:.1f}", flush=True)


if __name__ == "__main__":
    jax.config.update("jax_enable_x64", True)
    np.set_printoptions(precision=4)
    main()
