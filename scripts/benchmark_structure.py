"""Benchmark: a 20-degree-of-freedom modal structure carrying two nonlinear
absorbers, a steady-state sweep of 256 frequencies, absorber_jax against a scipy loop.

Scene: a 20-storey shear building (1 t floors, 2 MN/m storeys, 2 % modal damping) as its
modal model (all 20 modes, observed at every floor) under a ground acceleration of
0.1 m/s² (load = floor masses), with two friction dampers (smoothed Coulomb μ = 0.3,
eps = 1 mm/s, N = 300 N): 300 kg at the roof tuned to mode 1, 200 kg at floor 17 tuned to
mode 2.  Band 0.7–1.4 ω1.  State: 40 modal + 4 damper states.

- absorber_jax: ``frequency_response`` (vmapped shooting, rtol = atol = 1e-7; ``--root
  chord`` by default: lanes of 4 neighbouring frequencies, each point from its neighbour's
  orbit and Floquet monodromy, see ``Shooting``; ``--root newton`` for a Jacobian per Newton
  step), on one CPU device per core (``aj.use_cpu_cores``; ``--devices 1`` for one), timed on
  a second identical call (the first compiles);
- scipy: ``solve_ivp`` (DOP853, rtol 1e-8) of the same ODE in numpy, marched a period at a
  time until the Poincaré samples settle (``benchmark_sweep.march_until_settled``, 1e-4),
  on ``--scipy-points`` frequencies, its mean time per frequency extrapolated to 256.

Prints times, the speed ratio, the Newton iteration counts and the largest relative
difference of the roof amplitude on the common frequencies; appends them to FILE with
``--out`` (docs/benchmark_structure.txt holds the runs).

    python scripts/benchmark_structure.py [--points 256] [--scipy-points 4] [--root chord]
                                          [--devices N] [--out FILE]
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np
from scipy.integrate import solve_ivp

import absorber_jax as aj

sys.path.insert(0, os.path.dirname(__file__))
from benchmark_sweep import march_until_settled  # noqa: E402

N_FLOORS, F0, RTOL = 20, 0.1, 1e-7


def scene():
    n = N_FLOORS
    b = aj.shear_building([1e3] * n, [2e6] * n, modal_damping=0.02)
    w = np.asarray(b.natural_frequencies())
    law = aj.Coulomb(mu=0.3, eps=1e-3)
    els = [aj.FrictionDamper(f"floor{n}", m=300.0, k=300.0 * (w[0] / 1.02) ** 2, c=0.0,
                             normal_force=300.0, friction=law),
           aj.FrictionDamper(f"floor{n - 3}", m=200.0, k=200.0 * (w[1] / 1.02) ** 2, c=0.0,
                             normal_force=300.0, friction=law)]
    system = aj.StructuralSystem(b.modal(), els, load=dict(zip(b.dof_names, [1e3] * n)),
                                 observe=f"floor{n}")
    return system, w


def numpy_rhs(system):
    """The same ODE in plain numpy: modal coordinates, then each damper's (u, w)."""
    st = system.structure
    Phi, C, K = (np.asarray(a) for a in (st.dof_map, st.damping, st.stiffness))
    Minv = np.asarray(system.mass_inverse)
    load = np.asarray(system.load)
    n = Phi.shape[1]
    dampers = [(st.dof_index(e.dof), float(e.m), float(e.k), float(e.c),
                float(e.friction.mu) * float(e.normal_force), float(e.friction.eps))
               for e in system.elements]

    def f(t, s, amp, om):
        q, qd = s[:n], s[n:2 * n]
        force = load * amp * np.sin(om * t)
        fh = []
        for j, (i, _m, k, c, fc, eps) in enumerate(dampers):
            u, w = s[2 * n + 2 * j], s[2 * n + 2 * j + 1]
            fj = k * u + c * w - fc * np.tanh(-w / eps)
            force[i] += fj
            fh.append(fj)
        qdd = Minv @ (Phi.T @ force - C @ qd - K @ q)
        a = Phi @ qdd
        out = [qd, qdd]
        for j, (i, m, *_) in enumerate(dampers):
            out.append([s[2 * n + 2 * j + 1], -fh[j] / m - a[i]])
        return np.concatenate([np.ravel(o) for o in out])

    return f, 2 * n + 2 * len(dampers)


def scipy_point(system, om):
    f, dim = numpy_rhs(system)
    T = 2 * np.pi / om
    y = [np.zeros(dim)]

    def period(k):
        y[0] = solve_ivp(f, (k * T, (k + 1) * T), y[0], method="DOP853", rtol=1e-8,
                         atol=1e-11, args=(F0, om)).y[:, -1]
        return y[0]

    periods = march_until_settled(period, 1e-4, 2000)
    ts = np.linspace(0, T, 4097)  # half peak-to-peak of samples: (pi/4096)^2/2 = 3e-7 low
    sol = solve_ivp(f, (0, T), y[0], method="DOP853", rtol=1e-10, atol=1e-13, args=(F0, om),
                    t_eval=ts)
    roof = np.asarray(system.structure.dof_map)[N_FLOORS - 1] @ sol.y[:N_FLOORS]
    return 0.5 * np.ptp(roof), periods


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--points", type=int, default=256)
    ap.add_argument("--scipy-points", type=int, default=4)
    ap.add_argument("--root", default="chord", choices=("chord", "newton"))
    ap.add_argument("--devices", type=int, default=None,
                    help="CPU devices (default: one per core, see aj.use_cpu_cores)")
    ap.add_argument("--out", default=None)
    a = ap.parse_args()
    ndev = aj.use_cpu_cores(a.devices)     # before any JAX computation
    system, w = scene()
    om = np.linspace(0.7 * w[0], 1.4 * w[0], a.points)
    t0 = time.perf_counter()
    # the whole sweep once first: it compiles every program the timed run uses (a chord
    # sweep's lanes hold ceil(points / 64) neighbours, so a shorter grid compiles another)
    kw = dict(amplitude=F0, rtol=RTOL, atol=RTOL, chunk_size=64, root=a.root)
    aj.frequency_response(system, om, **kw)
    t_compile = time.perf_counter() - t0
    t0 = time.perf_counter()
    fr = aj.frequency_response(system, om, progress=True, **kw)
    t_jax = time.perf_counter() - t0
    idx = np.linspace(0, a.points - 1, a.scipy_points).round().astype(int)
    t0 = time.perf_counter()
    sp = [scipy_point(system, om[i]) for i in idx]
    t_sp = (time.perf_counter() - t0) / len(idx) * a.points
    diff = max(abs(fr.amplitude[i] - s[0]) / s[0] for i, s in zip(idx, sp))
    lines = [
        f"## 20-DOF modal structure + 2 friction dampers, {a.points} frequencies",
        f"- absorber_jax (root={a.root}, {ndev} CPU device(s)): {t_jax:.2f} s after compilation "
        f"({t_compile:.1f} s for the same sweep with compilation); {len(fr.failures())} failed, "
        f"{int((~fr.stable).sum())} unstable; root-finder steps median "
        f"{np.median(fr.iterations):.0f}, max {fr.iterations.max()}",
        f"- scipy DOP853 marching: {t_sp:.1f} s extrapolated from {len(idx)} frequencies "
        f"(periods marched: {[s[1] for s in sp]})",
        f"- ratio scipy / absorber_jax: {t_sp / t_jax:.1f}x; largest relative difference of "
        f"the roof amplitude on the common frequencies: {diff:.1e}",
    ]
    print("\n".join(lines))
    if a.out:
        with open(a.out, "a") as fh:
            fh.write("\n\n" + "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
