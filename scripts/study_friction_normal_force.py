"""Design study: the optimal normal force N of a friction absorber.

Too small an N and the absorber slides freely (an undamped tuned absorber: two sharp peaks);
too large and it sticks (one 1.2 kg resonance damped by the primary alone).  Near the best N
it sticks for part of each cycle.  At the library's defaults (the exact, event-driven Coulomb
law): a (N × frequency) grid in one vmapped call maps the band peak against N, a dense scan
between the grid's best neighbours refines the optimum, and ``tune`` finds it by gradient
descent from N = 2 N; all three are plotted and written to JSON.

    python scripts/study_friction_normal_force.py [--out docs/studies] [--quick]
"""

import argparse
import json
import os
import time

import numpy as np

import absorber_jax as aj

BAND = (70.0, 120.0)
F0 = 10.0


def band_peaks(base, om, Ns, **kw):
    grid = aj.frequency_response(base, om, amplitude=F0, params={"N": Ns}, **kw)
    ok = np.all(grid.status == 0, axis=1)
    return grid, np.where(ok, grid.amplitude.max(axis=1), np.nan)


def main(out, quick):
    os.makedirs(out, exist_ok=True)
    base = aj.FrictionAbsorber(m1=1.0, k1=1e4, c1=2.0, m2=0.2, k2=1.8e3, c2=0.0, normal_force=2.0,
                               friction=aj.Coulomb(mu=0.5))
    om = np.linspace(*BAND, 16 if quick else 48)
    Ns = np.geomspace(0.01, 200.0, 8 if quick else 30)
    t = time.perf_counter()
    grid, peaks = band_peaks(base, om, Ns, progress=True)
    first = time.perf_counter() - t
    t = time.perf_counter()
    grid, peaks = band_peaks(base, om, Ns)
    grid_s = time.perf_counter() - t
    print(f"grid {len(Ns)} N x {len(om)} ω: {grid_s:.1f} s after compilation "
          f"({first:.1f} s with it); failed {int((grid.status != 0).sum())}, "
          f"unstable {int((~grid.stable).sum())}", flush=True)
    i = int(np.nanargmin(peaks))
    # refine between the grid's neighbours of its best N (same frequencies)
    Nf = np.geomspace(Ns[max(i - 1, 0)], Ns[min(i + 1, len(Ns) - 1)], 9 if quick else 41)
    fine, fine_peaks = band_peaks(base, om, Nf)
    j = int(np.nanargmin(fine_peaks))
    import optax

    steps = 10 if quick else 100
    t = time.perf_counter()
    tuned, hist = aj.tune(base, {"N": (0.01, 200.0)}, BAND, amplitude=F0, steps=steps,
                          objective=aj.objectives.SmoothPeak(n_freq=len(om)),
                          progress=True, confirm=False,
                          optimizer=optax.adam(optax.cosine_decay_schedule(0.05, steps, 0.05)))
    tune_s = time.perf_counter() - t
    n_opt = hist["best"]["N"]
    peak_tuned = float(hist["amplitude_after"].max())
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(1, 3, figsize=(15, 4.2))
    axs[0].loglog(Ns, peaks * 1e3, "o-", label=f"band peak, grid ({len(Ns)} N)")
    axs[0].loglog(Nf, fine_peaks * 1e3, ".-", color="tab:green", label="refined scan")
    axs[0].axvline(n_opt, color="r", ls="--", label=f"tuned N = {n_opt:.3g} N")
    axs[0].set(xlabel="normal force N [N]", ylabel="peak primary amplitude [mm]",
               title="friction absorber: band peak against N")
    axs[0].legend(fontsize=8)
    for N in (Ns[0], n_opt, Ns[-1]):
        frf = aj.frequency_response(aj.replace_params(base, {"N": float(N)}), om, amplitude=F0)
        line, = axs[1].plot(om, frf.amplitude * 1e3, label=f"N = {N:.3g} N")
        uns = ~frf.stable
        axs[1].plot(om[uns], frf.amplitude[uns] * 1e3, "x", color=line.get_color())
    axs[1].set(xlabel="ω [rad/s]", ylabel="primary amplitude [mm]",
               title="response curves (x: unstable)")
    axs[1].legend(fontsize=8)
    axs[2].semilogx(hist["params"]["N"], np.asarray(hist["objective"]) * 1e3, ".-")
    axs[2].plot([2.0], [hist["objective"][0] * 1e3], "ko", label="start N = 2 N")
    axs[2].axvline(Nf[j], color="tab:green", ls=":", label=f"refined optimum {Nf[j]:.3g} N")
    axs[2].set(xlabel="N [N]", ylabel="objective (smooth band peak) [mm]",
               title=f"tune: {steps} Adam steps")
    axs[2].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "friction_normal_force.png"), dpi=110)
    res = {
        "law": "Coulomb(mu=0.5), exact (library default)", "F0_N": F0, "band_rad_s": BAND,
        "omegas": len(om), "N_grid": Ns.tolist(), "peak_mm": (peaks * 1e3).tolist(),
        "grid_failed_points": int((grid.status != 0).sum()),
        "grid_unstable_points": int((~grid.stable).sum()),
        "grid_seconds_after_compile": grid_s, "grid_seconds_with_compile": first,
        "N_grid_best": float(Ns[i]), "peak_grid_best_mm": float(peaks[i] * 1e3),
        "N_refined": Nf.tolist(), "peak_refined_mm": (fine_peaks * 1e3).tolist(),
        "N_refined_best": float(Nf[j]), "peak_refined_best_mm": float(fine_peaks[j] * 1e3),
        "N_tuned": n_opt, "peak_tuned_mm": peak_tuned * 1e3, "tune_steps": steps,
        "tune_seconds": tune_s, "tune_N_history": hist["params"]["N"],
        "N_tuned_vs_refined": n_opt / float(Nf[j]) - 1.0,
        "peak_tuned_vs_refined": peak_tuned / float(fine_peaks[j]) - 1.0,
    }
    with open(os.path.join(out, "friction_normal_force.json"), "w") as fh:
        json.dump(res, fh, indent=2)
    print(json.dumps({k: res[k] for k in ("N_grid_best", "N_refined_best", "N_tuned",
                                          "peak_refined_best_mm", "peak_tuned_mm",
                                          "N_tuned_vs_refined", "peak_tuned_vs_refined",
                                          "grid_seconds_after_compile")}))


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="docs/studies")
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args()
    main(a.out, a.quick)
