"""Design study: the optimal normal force N of a friction absorber.

Too small an N and the absorber slides freely (an undamped tuned absorber: two sharp peaks);
too large and it sticks (one 1.2 kg resonance damped by the primary alone).  A (N × frequency)
grid in one vmapped call maps the band peak against N; ``tune`` then finds the optimum by
gradient descent, and both are plotted.

    python scripts/study_friction_normal_force.py [--out studies] [--quick]
"""

import argparse
import json
import os

import numpy as np

import absorber_jax as aj


def main(out, quick):
    os.makedirs(out, exist_ok=True)
    base = aj.FrictionAbsorber(m1=1.0, k1=1e4, c1=2.0, m2=0.2, k2=1.8e3, c2=0.0, normal_force=2.0,
                               friction=aj.Coulomb(mu=0.5, eps=1e-3))
    band = (70.0, 120.0)
    om = np.linspace(*band, 16 if quick else 48)
    Ns = np.geomspace(0.01, 200.0, 8 if quick else 30)
    grid = aj.frequency_response(base, om, amplitude=10.0, params={"N": Ns}, progress=True)
    peaks = np.where(np.all(grid.status == 0, axis=1), grid.amplitude.max(axis=1), np.nan)
    import optax

    steps = 10 if quick else 120
    tuned, hist = aj.tune(base, ["N"], band, amplitude=10.0, steps=steps, n_freq=len(om),
                          bounds={"N": (0.01, 200.0)}, progress=True, confirm=False,
                          optimizer=optax.adam(optax.cosine_decay_schedule(0.2, steps, 0.05)))
    n_opt = hist["best"]["N"]
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(1, 2, figsize=(11, 4))
    axs[0].loglog(Ns, peaks * 1e3, "o-", label="band peak (grid)")
    axs[0].axvline(n_opt, color="r", ls="--", label=f"tuned N = {n_opt:.3g} N")
    axs[0].set(xlabel="normal force N [N]", ylabel="peak primary amplitude [mm]",
               title="friction absorber: peak against N")
    axs[0].legend()
    for N in (Ns[0], n_opt, Ns[-1]):
        frf = aj.frequency_response(aj.replace_params(base, {"N": float(N)}), om, amplitude=10.0)
        axs[1].plot(om, frf.amplitude * 1e3, label=f"N = {N:.3g} N")
    axs[1].set(xlabel="ω [rad/s]", ylabel="primary amplitude [mm]", title="response curves")
    axs[1].legend()
    fig.tight_layout()
    fig.savefig(os.path.join(out, "friction_normal_force.png"), dpi=110)
    res = {"N_grid": Ns.tolist(), "peak_mm": (peaks * 1e3).tolist(), "N_tuned": n_opt,
           "peak_tuned_mm": float(hist["amplitude_after"].max() * 1e3)}
    with open(os.path.join(out, "friction_normal_force.json"), "w") as fh:
        json.dump(res, fh, indent=2)
    print(json.dumps({k: res[k] for k in ("N_tuned", "peak_tuned_mm")}))


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="studies")
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args()
    main(a.out, a.quick)
