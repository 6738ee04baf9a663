"""Design study: the optimal clearance and contact damping of the Table 1 impact absorber.

A (gap × c1) grid of band peaks, every design × frequency point in vmapped calls, with the
gradient-tuned optimum from the Table 1 design marked on it.

    python scripts/study_impact_clearance_damping.py [--out studies] [--quick]
"""

import argparse
import json
import os

import numpy as np

import absorber_jax as aj


def main(out, quick):
    os.makedirs(out, exist_ok=True)
    system, forcing = aj.presets.impact("kelvin_voigt")
    band = (25.0, 45.0)
    om = np.linspace(*band, 12 if quick else 32)
    gaps = np.geomspace(1e-4, 3e-3, 5 if quick else 12)
    c1s = np.geomspace(2.0, 80.0, 5 if quick else 12)
    G, C = np.meshgrid(gaps, c1s, indexing="ij")
    grid = aj.frequency_response(system, om, amplitude=2.0,
                                 params={"gap": G.ravel(), "c1": C.ravel()}, progress=True)
    ok = np.all(grid.status == 0, axis=1)
    peaks = np.where(ok, grid.amplitude.max(axis=1), np.nan).reshape(G.shape)
    tuned, hist = aj.tune(system, ["gap", "c1"], band, amplitude=2.0, steps=8 if quick else 30,
                          n_freq=len(om), bounds={"gap": (5e-5, 5e-3), "c1": (0.5, 200.0)},
                          progress=True, confirm=not quick, confirm_points=8)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 5))
    cs = ax.contourf(gaps * 1e3, c1s, peaks.T * 1e3, levels=20, cmap="viridis")
    fig.colorbar(cs, label="band peak of x1 [mm]")
    ax.plot(np.array(hist["params"]["gap"]) * 1e3, hist["params"]["c1"], "w.-", lw=0.8,
            label="gradient descent")
    ax.plot(hist["best"]["gap"] * 1e3, hist["best"]["c1"], "r*", ms=12, label="tuned")
    ax.set(xscale="log", yscale="log", xlabel="clearance d [mm]",
           ylabel="contact damping c1 [N s/m]", title="Table 1 impact absorber, 25–45 rad/s")
    ax.legend()
    fig.tight_layout()
    fig.savefig(os.path.join(out, "impact_clearance_damping.png"), dpi=110)
    res = {"tuned": hist["best"], "peak_before_mm": float(hist["amplitude_before"].max() * 1e3),
           "peak_after_mm": float(hist["amplitude_after"].max() * 1e3),
           "grid_best_mm": float(np.nanmin(peaks) * 1e3), "grid_failed_designs": int((~ok).sum())}
    with open(os.path.join(out, "impact_clearance_damping.json"), "w") as fh:
        json.dump(res, fh, indent=2)
    print(json.dumps(res))


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="studies")
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args()
    main(a.out, a.quick)
