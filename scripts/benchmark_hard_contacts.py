"""Benchmark: hard contacts, where real impact dampers work.

Scenes: ``ImpactAbsorber(M=1, k=1e3, c=0.5, m=0.2, gap=2e-3)`` with
``KelvinVoigt(stiffness=2e4, damping=2, adhesive=True)`` or
``Hertz(stiffness=1e6, damping=2, adhesive=True)``,
F0 = 3 N, band 20–45 rad/s.

- **Attractor map at 30 rad/s** (``aj.attractors`` at its defaults: 32 initial states,
  marching budget 2000 periods, ``give_up`` 500, a 40-period statistics window carrying a
  Lyapunov tangent), timed in a fresh process (compilation included) and again (compiled).
  Against scipy: ``solve_ivp`` (DOP853, rtol 1e-8) of the same smoothed ODE in numpy
  (``benchmark_sweep.numpy_rhs``),
  period by period, over the periods absorber_jax marched plus the window for one initial
  state, extrapolated to the 32 states.
- **Continuation in ω over 20–45 rad/s** from both ends of the band (``direction="up"``
  from 20, ``"down"`` from 45), each timed with its compilation: points, the range it
  covers, how it ended, bifurcations found.
- **Band continuation** (``aj.band_continuation``, 8 starts, 60 points per half-branch at
  most, its default 2 fill passes), timed with its compilation: the parameter ranges the
  half-branches cover together, points, bifurcations.  Integrator tolerance ``--band-rtol``
  (default 1e-7: on the Kelvin–Voigt scene the folds, Neimark–Sacker and period-doubling
  values agree with rtol 1e-9 to 4 digits, at ~2/3 of the time).

    python scripts/benchmark_hard_contacts.py [--scenes kv,hertz] [--parts map,cont,band]
                                              [--scipy-periods 40] [--band-rtol 1e-7]
                                              [--devices N] [--out FILE]

Prints each result as it comes; ``--out`` appends them to FILE
(docs/benchmark_hard_contacts.txt holds the last run).
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
from benchmark_sweep import numpy_rhs  # noqa: E402

BAND, F0, OMEGA_MAP = (20.0, 45.0), 3.0, 30.0
LINES = []


def report(line):
    print(line, flush=True)
    LINES.append(line)


def scene(name):
    contact = (aj.KelvinVoigt(stiffness=2e4, damping=2.0, adhesive=True) if name == "kv"
               else aj.Hertz(stiffness=1e6, damping=2.0, adhesive=True))
    return aj.ImpactAbsorber(M=1.0, k=1e3, c=0.5, m=0.2, gap=2e-3, contact=contact)


def scipy_lane_seconds(system, y0, periods):
    """Seconds for scipy to march one initial state ``periods`` forcing periods."""
    f, _ = numpy_rhs(system)
    T = 2 * np.pi / OMEGA_MAP
    y = np.asarray(y0, dtype=float)
    t0 = time.perf_counter()
    for k in range(periods):
        y = solve_ivp(f, (k * T, (k + 1) * T), y, method="DOP853", rtol=1e-8, atol=1e-11,
                      args=(F0, OMEGA_MAP)).y[:, -1]
    return time.perf_counter() - t0


def attractor_map(name, scipy_periods):
    system = scene(name)
    forcing = aj.Harmonic(amplitude=F0, omega=OMEGA_MAP)
    t0 = time.perf_counter()
    m = aj.attractors(system, forcing)
    t_first = time.perf_counter() - t0
    t0 = time.perf_counter()
    m = aj.attractors(system, forcing)
    t_again = time.perf_counter() - t0
    marched = int(np.max(m.steady.iterations))
    lanes, window = m.initial_states.shape[0], 40
    t_lane = scipy_lane_seconds(system, m.initial_states[0], scipy_periods)
    t_sp = t_lane / scipy_periods * (marched + window) * lanes
    report(f"[{name}] attractor map at {OMEGA_MAP} rad/s: {t_first:.1f} s with compilation, "
           f"{t_again:.1f} s compiled; periods marched {marched} (+{window} window) x {lanes} "
           f"states; scipy DOP853 {t_sp:.0f} s extrapolated from {scipy_periods} periods of "
           f"one state: {t_sp / t_again:.0f}x (compiled), {t_sp / t_first:.0f}x (with "
           f"compilation)")
    for a in m.attractors:
        report("    " + str({k: (round(v, 5) if isinstance(v, float) else v)
                             for k, v in a.summary().items()}))


def continuation(name):
    system = scene(name)
    for start, direction in ((BAND[0], "up"), (BAND[1], "down")):
        forcing = aj.Harmonic(amplitude=F0, omega=start)
        t0 = time.perf_counter()
        br = aj.continuation(system, forcing, "omega", bounds=BAND, direction=direction)
        dt = time.perf_counter() - t0
        kinds = {k: len(br.of_kind(k)) for k in ("fold", "period_doubling", "neimark_sacker")}
        v = br.values
        report(f"[{name}] continuation from {start} {direction}: {dt:.1f} s with compilation, "
               f"{len(v)} points covering {v.min():.3f}-{v.max():.3f} rad/s, ended "
               f"{br.termination}; stable {int(np.sum(br.stable))}; bifurcations {kinds}; "
               f"corrector iterations {np.bincount(np.asarray(br.steady.iterations)).tolist()}")


def band(name, rtol):
    system = scene(name)
    t0 = time.perf_counter()
    brs = aj.band_continuation(system, aj.Harmonic(amplitude=F0, omega=BAND[0]), "omega",
                               bounds=BAND, starts=8, method=aj.PseudoArclength(max_points=60),
                               integrator=aj.Integrator(rtol=rtol, atol=rtol))
    dt = time.perf_counter() - t0
    spans = sorted((b.values[b.ok].min(), b.values[b.ok].max()) for b in brs if b.ok.any())
    covered = []
    for a, b in spans:
        if covered and a <= covered[-1][1]:
            covered[-1][1] = max(covered[-1][1], b)
        else:
            covered.append([a, b])
    kinds = {k: sum(len(b.of_kind(k)) for b in brs)
             for k in ("fold", "period_doubling", "neimark_sacker")}
    ends = [b.termination for b in brs]
    report(f"[{name}] band_continuation, 8 starts over {BAND[0]}-{BAND[1]} rad/s, rtol = atol "
           f"= {rtol:g}, fill 2: {dt:.1f} s "
           f"with compilation, {sum(len(b) for b in brs)} points on {len(brs)} half-branches "
           f"(ended: {dict((e, ends.count(e)) for e in sorted(set(ends)))}); covered "
           f"{', '.join(f'{a:.3f}-{b:.3f}' for a, b in covered)} rad/s; stable points "
           f"{sum(int(b.stable.sum()) for b in brs)}; bifurcations {kinds}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenes", default="kv,hertz")
    ap.add_argument("--parts", default="map,cont")
    ap.add_argument("--scipy-periods", type=int, default=40)
    ap.add_argument("--band-rtol", type=float, default=1e-7)
    ap.add_argument("--devices", type=int, default=None,
                    help="CPU devices (default: one per core, see aj.use_cpu_cores)")
    ap.add_argument("--out", default=None)
    a = ap.parse_args()
    report(f"{aj.use_cpu_cores(a.devices)} CPU device(s)")     # before any JAX computation
    for name in a.scenes.split(","):
        if "map" in a.parts:
            attractor_map(name, a.scipy_periods)
        if "cont" in a.parts:
            continuation(name)
        if "band" in a.parts:
            band(name, a.band_rtol)
    if a.out:
        with open(a.out, "a") as fh:
            fh.write("\n".join(LINES) + "\n")


if __name__ == "__main__":
    main()
