"""Stiff bristles: LuGre with sigma0 = 1e8 N/m (the extreme case of tests/test_extreme.py:
steady state and multipliers at the defaults in under 2 minutes, checked against
marching).

Scene: FrictionAbsorber(m1=1, k1=1e4, c1=2, m2=1, k2=1e4, c2=0, N=2 N),
LuGre(mu_c=0.5, mu_s=0.6, v_s=1e-2, sigma0=1e8, sigma1=1e2), F0 = 10 N, omega = 50 rad/s.

What the script establishes, each step by an independent route:

1. ``steady_state`` at the defaults (the law's default is |v| exact, eps = 0): time, Newton
   steps, amplitude, Floquet multipliers, the largest bristle force against mu_s N.
2. Marching from rest: (a) the library's ``Marching`` solve; (b) the Poincaré samples
   x(kT) of a plain ``simulate`` at tighter tolerances, whose distance to the shot orbit must
   fall like |mu|max^k.
3. (``--smoothed``) Why the default is exact: with |v| smoothed as v tanh(v/eps), eps = 1e-4,
   shooting from the rigidly stuck response converges to a fully stuck orbit whose bristles
   hold ~5 N against mu_s N = 1.2 N: below eps the smoothed |v| makes the bristle a plain
   linear spring, and stiff bristles stick at ~1e-6 m/s.  The exact law from the same start
   (no such orbit exists for it) is reported beside it.

    python scripts/study_lugre_stiff_bristles.py [--out docs/studies] [--periods 150] [--smoothed]
"""

import argparse
import json
import os
import time

import numpy as np

import absorber_jax as aj

KW = dict(m1=1.0, k1=1e4, c1=2.0, m2=1.0, k2=1e4, c2=0.0, normal_force=2.0)
LAW = dict(mu_c=0.5, mu_s=0.6, v_s=1e-2, sigma1=1e2, sigma2=0.0)
FORCING = aj.Harmonic(amplitude=10.0, omega=50.0)
RTOL, ATOL = 1e-10, 1e-14       # z ~ mu_c N / sigma0 = 1e-8 m: atol well below it
MAX_STEPS = 2_000_000           # ~145k Tsit5 steps per period


def system_at(sigma0, eps=0.0):
    return aj.FrictionAbsorber(friction=aj.LuGre(sigma0=sigma0, eps=eps, **LAW), **KW)


def orbit_over_period(system, y0, n=801):
    T = FORCING.period
    tr = aj.simulate(system, FORCING, T, y0=y0, ts=np.linspace(0.0, T, n), rtol=RTOL,
                     atol=ATOL, max_steps=MAX_STEPS)
    return np.linspace(0.0, T, n), np.asarray(tr.ys)


def bristle_force_max(system, ys):
    return float(system.friction.sigma0) * float(np.abs(ys[:, 4]).max())


def stuck_start(report):
    """Shooting from the rigidly stuck response (the absorber riding on the primary: Coulomb
    with N = 1e6, exact stick), bristles unloaded, for the smoothed law (eps = 1e-4) and the
    exact one.  Holding the absorber on needs m2 omega^2 x ~ 5 N, four times mu_s N."""
    rigid = aj.FrictionAbsorber(friction=aj.Coulomb(mu=0.5), **{**KW, "normal_force": 1e6})
    x = np.asarray(aj.steady_state(rigid, FORCING).state)
    rows = {}
    for name, eps in (("smoothed_eps_1e-4", 1e-4), ("exact", 0.0)):
        system = system_at(1e8, eps=eps)
        t = time.perf_counter()
        ss = aj.steady_state(system, FORCING, guess=np.r_[x, 0.0],
                             method=aj.Shooting(retry=False, newton_steps=20))
        row = {"status": aj.describe(ss.status), "newton_steps": int(ss.iterations),
               "seconds": time.perf_counter() - t}
        if int(ss.status) == 0:
            _, ys = orbit_over_period(system, np.asarray(ss.state))
            row.update(amplitude_mm=float(ss.amplitude) * 1e3,
                       multiplier_moduli=sorted(np.abs(np.asarray(ss.multipliers)).tolist())[::-1],
                       bristle_force_max_N=bristle_force_max(system, ys),
                       relative_speed_max_m_s=float(np.abs(ys[:, 3] - ys[:, 1]).max()))
        rows[name] = row
        print("from the stuck response,", name, row, flush=True)
    report["shooting_from_the_stuck_response"] = rows


def main(out, periods, smoothed):
    os.makedirs(out, exist_ok=True)
    system = system_at(1e8)
    muN = LAW["mu_s"] * KW["normal_force"]
    report = {"scene": "LuGre sigma0=1e8, F0=10 N, omega=50 rad/s, |v| exact (the default)",
              "solver": aj.choose_solver(system, FORCING, rtol=1e-9),
              "static_friction_N": muN}

    t = time.perf_counter()
    ss = aj.steady_state(system, FORCING)
    seconds = time.perf_counter() - t
    x = np.asarray(ss.state)
    mult = np.asarray(ss.multipliers)
    ts, ys = orbit_over_period(system, x)
    report["steady_state_defaults"] = {
        "status": aj.describe(ss.status), "newton_steps": int(ss.iterations),
        "residual": float(ss.residual), "amplitude_mm": float(ss.amplitude) * 1e3,
        "stable": bool(ss.stable), "multiplier_moduli": sorted(np.abs(mult).tolist())[::-1],
        "bristle_force_max_N": bristle_force_max(system, ys),
        "seconds_with_compilation": seconds}
    print("steady_state", report["steady_state_defaults"], flush=True)

    t = time.perf_counter()
    ma = aj.steady_state(system, FORCING, method=aj.Marching(max_periods=400, n_max=2))
    report["marching_from_rest"] = {
        "status": aj.describe(ma.status), "periods": int(ma.iterations),
        "amplitude_mm": float(ma.amplitude) * 1e3,
        "amplitude_relative_difference": float(abs(ma.amplitude / ss.amplitude - 1)),
        "multiplier_moduli": sorted(np.abs(np.asarray(ma.multipliers)).tolist())[::-1],
        "seconds": time.perf_counter() - t}
    print("marching", report["marching_from_rest"], flush=True)

    # independent march: simulate at tighter tolerances, Poincaré samples against the shot state
    t = time.perf_counter()
    T = FORCING.period
    tr = aj.simulate(system, FORCING, periods * T, ts=np.arange(periods + 1) * T, rtol=RTOL,
                     atol=ATOL, max_steps=MAX_STEPS * periods)
    sec = np.asarray(tr.ys)
    scale = np.abs(ys).max(axis=0)
    dist = np.linalg.norm((sec - x) / scale, axis=1)
    k = np.arange(len(dist))
    tail = slice(len(dist) // 3, None)
    rate = float(np.exp(np.polyfit(k[tail], np.log(dist[tail]), 1)[0]))
    report["simulate_poincare"] = {"periods": periods, "seconds": time.perf_counter() - t,
                                   "final_scaled_distance_to_shot_state": float(dist[-1]),
                                   "observed_contraction_per_period": rate,
                                   "largest_multiplier_modulus": float(np.abs(mult).max())}
    print("simulate", report["simulate_poincare"], flush=True)

    if smoothed:
        stuck_start(report)

    with open(os.path.join(out, "lugre_stiff_bristles.json"), "w") as f:
        json.dump(report, f, indent=1)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(1, 3, figsize=(15, 4))
    axs[0].semilogy(k, dist, ".", ms=4, label="simulate from rest, x(kT)")
    axs[0].semilogy(k, dist[len(dist) // 3] * rate ** (k - len(dist) // 3), "k--",
                    label=f"fit {rate:.3f}^k  (|μ|max = {np.abs(mult).max():.3f})")
    axs[0].set(xlabel="forcing period k", ylabel="scaled distance to the shot orbit",
               title="marching from rest settles on the shot orbit")
    axs[0].legend()
    axs[1].plot(ts / T, (ys[:, 3] - ys[:, 1]) * 1e3)
    axs[1].set(xlabel="t / T", ylabel="relative velocity v2 - v1 [mm/s]",
               title=f"orbit: {float(ss.amplitude) * 1e3:.4f} mm, stick and slip")
    axs[2].plot(ts / T, float(system.friction.sigma0) * ys[:, 4], label="σ0 z")
    for sgn in (1, -1):
        axs[2].axhline(sgn * muN, color="C3", ls="--", label="± μs N" if sgn > 0 else None)
    axs[2].set(xlabel="t / T", ylabel="bristle force [N]", title="bristle force within μs N")
    axs[2].legend()
    fig.tight_layout()
    fig.savefig(os.path.join(out, "lugre_stiff_bristles.png"), dpi=120)
    print("written", os.path.join(out, "lugre_stiff_bristles.json"))


if __name__ == "__main__":
    p = argparse.ArgumentParser()
    p.add_argument("--out", default="docs/studies")
    p.add_argument("--periods", type=int, default=150)
    p.add_argument("--smoothed", action="store_true")
    a = p.parse_args()
    main(a.out, a.periods, a.smoothed)
