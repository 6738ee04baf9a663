"""Stiff bristles: LuGre with sigma0 = 1e8 N/m (the extreme case of tests/test_extreme.py).

Scene: FrictionAbsorber(m1=1, k1=1e4, c1=2, m2=1, k2=1e4, c2=0, N=2 N),
LuGre(mu_c=0.5, mu_s=0.6, v_s=1e-2, sigma0=1e8, sigma1=1e2), F0 = 10 N, omega = 50 rad/s.

What the script establishes, each step by an independent route:

1. From rest, the response does not settle on a period-1 (or short-period) orbit: Poincaré
   samples x1(kT) over ``--periods`` forcing periods (simulate, tight tolerances) keep
   wandering.  The rigid-bristle limit (exact Stribeck stick-slip, the same mu_c, mu_s, v_s)
   does not settle either (marching: NOT_PERIODIC).
2. Shooting from the last marched state finds the period-1 orbit (Newton steps and residual
   printed) and its Floquet multipliers: it is unstable.
3. The instability is checked by direct integration (simulate, not the shooting flow): a small
   perturbation of the shot orbit grows per period at the rate of the largest multiplier.

    python scripts/study_lugre_stiff_bristles.py [--out docs/studies] [--periods 300]
"""

import argparse
import json
import os
import time

import numpy as np

import absorber_jax as aj

KW = dict(m1=1.0, k1=1e4, c1=2.0, m2=1.0, k2=1e4, c2=0.0, normal_force=2.0)
LAW = aj.LuGre(mu_c=0.5, mu_s=0.6, v_s=1e-2, sigma0=1e8, sigma1=1e2, sigma2=0.0)
FORCING = aj.Harmonic(amplitude=10.0, omega=50.0)
RTOL, ATOL = 1e-9, 1e-13        # z ~ mu_c N / sigma0 = 1e-8 m: atol well below it
MAX_STEPS = 2_000_000           # ~145k Tsit5 steps per period


def poincare(system, y0, periods):
    T = FORCING.period
    tr = aj.simulate(system, FORCING, periods * T, y0=y0, ts=np.arange(periods + 1) * T,
                     rtol=RTOL, atol=ATOL, max_steps=MAX_STEPS * max(periods, 1))
    return np.asarray(tr.ys)


def main(out, periods):
    os.makedirs(out, exist_ok=True)
    system = aj.FrictionAbsorber(friction=LAW, **KW)
    report = {"scene": "LuGre sigma0=1e8, F0=10 N, omega=50 rad/s",
              "solver": aj.choose_solver(system, FORCING, rtol=1e-9)}

    t = time.perf_counter()
    cache = os.path.join(out, f"lugre_stiff_bristles_poincare_{periods}.npy")
    if os.path.exists(cache):
        ys = np.load(cache)
    else:
        # three equal chunks (one compilation), each from the last state of the previous one
        chunks, y = [], np.zeros(system.num_states)
        for i in range(3):
            part = poincare(system, y, periods // 3)
            chunks.append(part if i == 0 else part[1:])
            y = part[-1]
        ys = np.concatenate(chunks)
        np.save(cache, ys)
    x1 = ys[:, 0]
    tail = x1[-min(50, len(x1) // 2):]
    report["march"] = {"periods": int(len(x1) - 1), "seconds": time.perf_counter() - t,
                       "x1_section_last50_spread_mm": float(np.ptp(tail) * 1e3),
                       "x1_section_last50_mean_mm": float(np.mean(tail) * 1e3)}
    print("march", report["march"], flush=True)

    rigid = aj.FrictionAbsorber(friction=aj.Stribeck(mu_c=0.5, mu_s=0.6, v_s=1e-2), **KW)
    t = time.perf_counter()
    rm = aj.steady_state(rigid, FORCING, method=aj.Marching(max_periods=400, n_max=8))
    report["rigid_limit_marching"] = {"status": aj.describe(rm.status),
                                      "seconds": time.perf_counter() - t}
    print("rigid-bristle limit", report["rigid_limit_marching"], flush=True)

    # shoot from the section sample that comes back closest to itself after one period (the
    # march passes near the unstable orbit now and then; scaled by each component's spread)
    spread = np.maximum(np.ptp(ys[periods // 3:], axis=0), 1e-300)
    ret = np.linalg.norm(np.diff(ys, axis=0) / spread, axis=1)
    k_best = int(periods // 3 + np.argmin(ret[periods // 3:]))
    y = ys[k_best]
    report["shooting_start"] = {"period": k_best, "scaled_return_distance": float(ret[k_best])}
    t = time.perf_counter()
    ss = aj.steady_state(system, FORCING, guess=y, method=aj.Shooting(retry=False),
                         max_steps=MAX_STEPS // 2)
    mult = np.asarray(ss.multipliers)
    report["shooting_from_marched"] = {
        "status": aj.describe(ss.status), "newton_steps": int(ss.iterations),
        "residual": float(ss.residual), "amplitude_mm": float(ss.amplitude) * 1e3,
        "stable": bool(ss.stable), "multiplier_moduli": sorted(np.abs(mult).tolist())[::-1],
        "seconds": time.perf_counter() - t}
    print("shooting", report["shooting_from_marched"], flush=True)

    # direct check of the leading multiplier: a perturbation of the orbit grows per period
    # at |mu|max (simulate, not the shooting flow; relative size 1e-7 of each component)
    x = np.asarray(ss.state)
    scale = np.maximum(np.abs(x), 1e-3 * np.max(np.abs(x[:4])))
    scale[4] = max(abs(x[4]), float(LAW.mu_c * KW["normal_force"] / LAW.sigma0))
    rng = np.random.default_rng(0)
    k = 6
    on = poincare(system, x, k)
    off = poincare(system, x + 1e-7 * scale * rng.standard_normal(x.size), k)
    dev = np.linalg.norm((off - on) / scale, axis=1)
    growth = dev[1:] / dev[:-1]
    report["perturbation_growth_per_period"] = growth.tolist()
    report["perturbation_growth_geometric_mean"] = float(np.exp(np.mean(np.log(growth))))
    report["orbit_drift_per_period_scaled"] = np.linalg.norm((on - x) / scale, axis=1).tolist()
    print("growth per period", growth, "geometric mean",
          report["perturbation_growth_geometric_mean"], "vs |mu|max", np.abs(mult).max(),
          flush=True)

    with open(os.path.join(out, "lugre_stiff_bristles.json"), "w") as f:
        json.dump(report, f, indent=1)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(1, 2, figsize=(11, 4))
    axs[0].plot(np.arange(len(x1)), x1 * 1e3, ".", ms=3, label="x1(kT), from rest")
    axs[0].axhline(x[0] * 1e3, color="C3", label="period-1 orbit (unstable), x1(0)")
    axs[0].set(xlabel="forcing period k", ylabel="x1(kT) [mm]",
               title="Poincaré section: no settled period-1 response")
    axs[0].legend()
    kk = np.arange(len(dev))
    axs[1].semilogy(kk, dev, "o-", label="perturbation of the shot orbit (simulate)")
    axs[1].semilogy(kk, dev[0] * np.abs(mult).max() ** kk, "k--",
                    label=f"|μ|max^k, |μ|max = {np.abs(mult).max():.3f} (shooting)")
    axs[1].set(xlabel="periods after the perturbation", ylabel="scaled deviation",
               title="instability of the period-1 orbit")
    axs[1].legend()
    fig.tight_layout()
    fig.savefig(os.path.join(out, "lugre_stiff_bristles.png"), dpi=120)
    print("written", os.path.join(out, "lugre_stiff_bristles.json"))


if __name__ == "__main__":
    p = argparse.ArgumentParser()
    p.add_argument("--out", default="docs/studies")
    p.add_argument("--periods", type=int, default=300)
    a = p.parse_args()
    main(a.out, a.periods)
