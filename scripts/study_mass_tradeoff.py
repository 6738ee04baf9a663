"""Design study: absorber mass against the tuned band peak.

For each mass ratio μ = m/M the absorber's contact stiffness and damping are tuned (peak
objective) for the linear TMD limit (gap = 0) on an undamped primary, where Den Hartog's
peak sqrt(1 + 2/μ) is the classical reference, and for the Table 1 impact absorber (gap 1 mm).

    python scripts/study_mass_tradeoff.py [--out studies] [--quick]
"""

import argparse
import json
import os

import numpy as np

import absorber_jax as aj


def main(out, quick):
    os.makedirs(out, exist_ok=True)
    mus = np.array([0.05, 0.1, 0.2, 0.4]) if quick else np.array([0.03, 0.05, 0.1, 0.15, 0.2,
                                                                   0.3, 0.4, 0.6])
    M, k = 1.0, 1e3
    wn = np.sqrt(k / M)
    rows = []
    for mu in mus:
        m = mu * M
        k1 = m * (wn / (1 + mu)) ** 2
        c1 = 2 * np.sqrt(3 * mu / (8 * (1 + mu) ** 3)) * np.sqrt(k1 * m)
        tmd = aj.ImpactAbsorber(M=M, k=k, c=0.0, m=m, gap=0.0,
                                contact=aj.KelvinVoigt(stiffness=1.1 * k1, damping=0.7 * c1))
        _, h_lin = aj.tune(tmd, ["k1", "c1"], (0.6 * wn, 1.4 * wn), amplitude=1.0,
                           steps=40 if quick else 100, n_freq=48, confirm=False)
        imp = aj.ImpactAbsorber(M=M, k=k, c=0.1, m=m, gap=1e-3,
                                contact=aj.KelvinVoigt(stiffness=400.0, damping=20.0))
        _, h_imp = aj.tune(imp, ["k1", "c1"], (25.0, 45.0), amplitude=2.0,
                           steps=5 if quick else 25, n_freq=16 if quick else 32, confirm=False)
        row = {"mu": float(mu), "tmd_peak_static": float(h_lin["amplitude_after"].max() * k),
               "den_hartog_peak_static": float(np.sqrt(1 + 2 / mu)),
               "impact_peak_mm": float(h_imp["amplitude_after"].max() * 1e3),
               "impact_peak_before_mm": float(h_imp["amplitude_before"].max() * 1e3)}
        print(row, flush=True)
        rows.append(row)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(1, 2, figsize=(11, 4))
    mu = [r["mu"] for r in rows]
    axs[0].plot(mu, [r["tmd_peak_static"] for r in rows], "o-", label="tuned (absorber_jax)")
    axs[0].plot(mu, [r["den_hartog_peak_static"] for r in rows], "k--",
                label="Den Hartog sqrt(1+2/μ)")
    axs[0].set(xlabel="mass ratio μ", ylabel="peak |X1| k / F0",
               title="linear TMD, undamped primary")
    axs[0].legend()
    axs[1].plot(mu, [r["impact_peak_before_mm"] for r in rows], "o-", color="0.5",
                label="Table 1 contact (k1 = 400, c1 = 20)")
    axs[1].plot(mu, [r["impact_peak_mm"] for r in rows], "o-", label="k1, c1 tuned")
    axs[1].set(xlabel="mass ratio μ", ylabel="band peak of x1 [mm]",
               title="impact absorber, gap 1 mm, 25–45 rad/s")
    axs[1].legend()
    fig.tight_layout()
    fig.savefig(os.path.join(out, "mass_tradeoff.png"), dpi=110)
    with open(os.path.join(out, "mass_tradeoff.json"), "w") as fh:
        json.dump(rows, fh, indent=2)


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="studies")
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args()
    main(a.out, a.quick)
