"""Reproduction of the paper's figures and a check of its conclusions.

``reproduce_paper(out_dir)`` writes one PNG per paper figure (2, 4, 6, 7, 9–20), a
``summary.json`` (amplitudes in mm, the keys say so) and ``amplitudes.csv`` (SI: metres,
each header with its unit) with the amplitudes we measured, and returns the summary.
``quick=True`` shortens every simulation (used by the tests).
"""

from __future__ import annotations

import csv
import json
import os
import time

import diffrax
import jax
import jax.numpy as jnp
import numpy as np

from .. import presets
from .._integration.simulate import REGIME_NAMES, simulate
from .._periodic.steady import steady_state

IMPACT_LABELS = {
    "kelvin_voigt": "linear (Kelvin–Voigt)",
    "hertz": "semi-linear (Hertz)",
    "hunt_crossley": "nonlinear (Hunt–Crossley)",
}
FRICTION_LABELS = {
    "coulomb": "Coulomb",
    "stribeck": "Stribeck",
    "dahl": "Dahl",
    "lugre": "LuGre",
    "stribeck_physical": "Stribeck (v_s = 1e-2)",
    "lugre_physical": "LuGre (v_s = 1e-2)",
}
REGIME_COLORS = ("#d0e4f5", "#fbe3c4", "#d9f0d3")


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _shade_regimes(ax, ts, regime):
    edges = np.flatnonzero(np.diff(regime)) + 1
    starts = np.concatenate([[0], edges])
    ends = np.concatenate([edges, [len(ts) - 1]])
    seen = set()
    for a, b in zip(starts, ends):
        r = int(regime[a])
        ax.axvspan(
            ts[a], ts[b], color=REGIME_COLORS[r], lw=0, label=None if r in seen else REGIME_NAMES[r]
        )
        seen.add(r)


def _bristle_response(law, N, x_amp, omega, periods=3):
    """Friction force of a law driven by X(t) = x_amp sin(ωt) (hysteresis loops)."""

    def rhs(t, z, args):
        return law.state_rate(x_amp * omega * jnp.cos(omega * t), z, N)

    ts = jnp.linspace(0, periods * 2 * jnp.pi / omega, 3000)
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(rhs),
        diffrax.Kvaerno5(),
        0.0,
        ts[-1],
        1e-5,
        law.initial_state(),
        saveat=diffrax.SaveAt(ts=ts),
        stepsize_controller=diffrax.PIDController(rtol=1e-8, atol=1e-12),
        max_steps=200000,
    )
    v = x_amp * omega * jnp.cos(omega * ts)
    f = jax.vmap(lambda vi, zi: law.force(vi, zi, N))(v, sol.ys)
    return np.asarray(x_amp * jnp.sin(omega * ts)), np.asarray(v), np.asarray(f)


def friction_curves(out_dir):
    """Figs. 9, 10, 15, 16: the friction laws' force curves (N = 1 N)."""
    plt = _plt()
    N = 1.0
    v = jnp.linspace(-0.05, 0.05, 2001)
    paths = []
    for fig, names in ((9, ("coulomb",)), (10, ("stribeck", "stribeck_physical"))):
        f, ax = plt.subplots(figsize=(6, 4))
        for name in names:
            law = presets.friction_law(name)
            ax.plot(
                v,
                law.force(v, None, N),
                label=f"{FRICTION_LABELS[name]}, eps = {float(law.eps):g} m/s",
            )
        ax.set(
            xlabel="relative velocity Ẋ [m/s]",
            ylabel="Fnl / N [-]",
            title=f"Fig. {fig}: {FRICTION_LABELS[names[0]]} friction force",
        )
        ax.axhline(0, color="k", lw=0.5)
        ax.legend(fontsize=8)
        paths.append(_save(f, out_dir, f"fig{fig:02d}_{names[0]}_force.png"))
    law = presets.friction_law("dahl")
    f, ax = plt.subplots(figsize=(6, 4))
    for amp in (2e-5, 5e-5, 2e-4):
        x, _, F = _bristle_response(law, N, amp, 50.0)
        ax.plot(x * 1e3, F, label=f"X amplitude {amp * 1e3:g} mm")
    ax.set(
        xlabel="relative displacement X [mm]",
        ylabel="Fnl [N]",
        title="Fig. 15: Dahl force (pre-sliding hysteresis, N = 1 N)",
    )
    ax.legend(fontsize=8)
    paths.append(_save(f, out_dir, "fig15_dahl_force.png"))
    f, ax = plt.subplots(figsize=(6, 4))
    law = presets.friction_law("lugre_physical")
    for amp in (1e-4, 1e-3):
        _, vv, F = _bristle_response(law, N, amp, 50.0)
        ax.plot(vv, F, label=f"LuGre (v_s = 1e-2), X amplitude {amp * 1e3:g} mm")
    vs = jnp.linspace(-0.05, 0.05, 801)
    ax.plot(vs, law.steady_force(vs, N), "k--", lw=1, label="steady sliding g(v) sign(v) + σ2 v")
    ax.set(
        xlabel="relative velocity Ẋ [m/s]",
        ylabel="Fnl [N]",
        title="Fig. 16: LuGre force (N = 1 N)",
        ylim=(-0.8, 0.8),
    )
    ax.legend(fontsize=8)
    paths.append(_save(f, out_dir, "fig16_lugre_force.png"))
    return paths


def _save(fig, out_dir, name):
    path = os.path.join(out_dir, name)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    _plt().close(fig)
    return path


def _amplitude_window(ts, x, t_from, t_to):
    sel = (ts >= t_from) & (ts <= t_to)
    return 0.5 * float(np.ptp(x[sel]))


def reproduce_paper(out_dir: str = "paper_figures", *, quick: bool = False, progress=True):
    """Write the paper's figures and the measured amplitudes to ``out_dir``; returns the
    summary dictionary (also written as ``summary.json``)."""
    from tqdm.auto import tqdm

    plt = _plt()
    os.makedirs(out_dir, exist_ok=True)
    t_imp = 1.0 if quick else 5.0
    ramp = 3.0 if quick else presets.FRICTION_RAMP
    t_fri = ramp * 1.25
    jobs = [("impact", n) for n in presets.IMPACT_SCENES] + [
        ("friction", n)
        for n in ("coulomb", "stribeck", "dahl", "lugre", "stribeck_physical", "lugre_physical")
    ]
    trajs, timings, rows = {}, {}, []
    bar = tqdm(jobs, desc="paper scenes", disable=not progress)
    for kind, name in bar:
        bar.set_postfix_str(name)
        if kind == "impact":
            system, forcing = presets.impact(name)
            t1 = t_imp
        else:
            system, forcing = presets.friction(name, ramp_time=ramp)
            t1 = t_fri
        tr = simulate(system, forcing, t1)  # compiles
        t = time.perf_counter()
        tr = simulate(system, forcing, t1)  # timed without compilation
        jax.block_until_ready(tr.ys)
        timings[name] = (time.perf_counter() - t) / t1
        trajs[name] = tr
    summary = {
        "impact": {},
        "friction": {},
        "assumptions": {
            "impact_gap_m": presets.IMPACT_GAP,
            "impact_eps_m": presets.IMPACT_EPS,
            "friction_normal_force_N": presets.FRICTION_NORMAL_FORCE,
            "friction_omega_rad_s": presets.FRICTION_OMEGA,
            "friction_F0_final_N": presets.FRICTION_F0,
            "friction_ramp_s": ramp,
            "friction_eps_m_s": presets.FRICTION_EPS,
        },
        "quick": quick,
    }

    # --- impact: Figs. 2, 4, 6, 7 ---
    figs = {"kelvin_voigt": 2, "hertz": 4, "hunt_crossley": 6}
    f7, ax7 = plt.subplots(figsize=(8, 4))
    for name in presets.IMPACT_SCENES:
        tr = trajs[name]
        ts, x1 = np.asarray(tr.ts), np.asarray(tr.x1)
        T = float(tr.forcing.period)
        amp = _amplitude_window(ts, x1, ts[-1] - 10 * T, ts[-1])
        rel = _amplitude_window(ts, np.asarray(tr.relative), ts[-1] - 10 * T, ts[-1])
        sys_, forc_ = presets.impact(name)
        marched = steady_state(sys_, forc_, method="marching")
        shot = steady_state(sys_, forc_, method="shooting")
        summary["impact"][name] = {
            "steady_marching_from_rest": {"x1_amplitude_mm": float(marched.amplitude) * 1e3,
                                          "period_multiple": int(marched.period_multiple),
                                          "stable": bool(marched.stable),
                                          "status": int(marched.status)},
            "steady_shooting_period1": {"x1_amplitude_mm": float(shot.amplitude) * 1e3,
                                        "stable": bool(shot.stable), "status": int(shot.status)},
            "x1_amplitude_mm": amp * 1e3,
            "relative_amplitude_mm": rel * 1e3,
            "seconds_per_simulated_second": timings[name],
            "steps": int(tr.num_steps),
            "solver": tr.solver,
        }
        rows.append(["impact", name, amp, rel, "", timings[name], int(tr.num_steps)])
        f, ax = plt.subplots(figsize=(8, 4))
        ax.plot(ts, x1 * 1e3, lw=0.8)
        ax.set(
            xlabel="t [s]",
            ylabel="x1 [mm]",
            title=f"Fig. {figs[name]}: primary displacement, {IMPACT_LABELS[name]} collision",
        )
        _save(f, out_dir, f"fig{figs[name]:02d}_{name}_x1.png")
        ax7.plot(ts, x1 * 1e3, lw=0.8, label=f"{IMPACT_LABELS[name]} ({amp * 1e3:.2f} mm)")
    ax7.set(
        xlabel="t [s]", ylabel="x1 [mm]", title="Fig. 7: primary displacement, all collision models"
    )
    ax7.legend(fontsize=8)
    _save(f7, out_dir, "fig07_impact_all_x1.png")

    # --- friction: curves (9, 10, 15, 16) and scenes (11–14, 17–20) ---
    friction_curves(out_dir)
    for name in ("coulomb", "stribeck", "dahl", "lugre", "stribeck_physical", "lugre_physical"):
        tr = trajs[name]
        ts, x1 = np.asarray(tr.ts), np.asarray(tr.x1)
        reg = np.asarray(tr.regime)
        rms = float(np.sqrt(np.mean(x1**2)))
        end_amp = _amplitude_window(ts, x1, ts[-1] - 0.2 * ramp, ts[-1])
        onset = {
            REGIME_NAMES[r]: (float(ts[np.argmax(reg == r)]) if (reg == r).any() else None)
            for r in range(3)
        }
        summary["friction"][name] = {
            "x1_rms_mm": rms * 1e3,
            "x1_final_amplitude_mm": end_amp * 1e3,
            "regime_onset_s": onset,
            "seconds_per_simulated_second": timings[name],
            "steps": int(tr.num_steps),
            "solver": tr.solver,
        }
        rows.append(
            ["friction", name, end_amp, "", rms, timings[name], int(tr.num_steps)]
        )
    pairs = (((11, 12, 13, 14), ("coulomb", "stribeck")), ((17, 18, 19, 20), ("dahl", "lugre")))
    for (fa, fb, fr, fx), names in pairs:
        for fig, name in zip((fa, fb), names):
            tr = trajs[name]
            ts = np.asarray(tr.ts)
            f, ax = plt.subplots(figsize=(8, 4))
            _shade_regimes(ax, ts, np.asarray(tr.regime))
            ax.plot(ts, np.asarray(tr.x1) * 1e3, "k", lw=0.5, label="x1")
            ax.set(
                xlabel="t [s]",
                ylabel="x1 [mm]",
                title=f"Fig. {fig}: primary displacement, {FRICTION_LABELS[name]} "
                f"(force ramps 0→{presets.FRICTION_F0:g} N)",
            )
            ax.legend(fontsize=8, loc="upper left")
            _save(f, out_dir, f"fig{fig:02d}_{name}_x1.png")
        f, axs = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
        for ax, name in zip(axs, names):
            tr = trajs[name]
            ts = np.asarray(tr.ts)
            _shade_regimes(ax, ts, np.asarray(tr.regime))
            ax.semilogy(ts, np.maximum(np.asarray(tr.force_ratio), 1e-4), "k", lw=0.4)
            ax.axhline(1.0, color="r", lw=0.8)
            ax.set(ylabel="|Fa| / |Fnl|", title=FRICTION_LABELS[name], ylim=(1e-3, 1e3))
            ax.legend(fontsize=7, loc="upper left")
        axs[-1].set_xlabel("t [s]")
        f.suptitle(f"Fig. {fr}: forces ratio Fa/Fnl (Fa = m2 Ẍ)")
        _save(f, out_dir, f"fig{fr:02d}_{names[0]}_{names[1]}_ratio.png")
        f, ax = plt.subplots(figsize=(8, 4))
        for name in names:
            tr = trajs[name]
            ax.plot(np.asarray(tr.ts), np.asarray(tr.x2) * 1e3, lw=0.5, label=FRICTION_LABELS[name])
        ax.set(xlabel="t [s]", ylabel="x2 [mm]", title=f"Fig. {fx}: absorber displacement")
        ax.legend(fontsize=8)
        _save(f, out_dir, f"fig{fx:02d}_{names[0]}_{names[1]}_x2.png")

    imp, fri = summary["impact"], summary["friction"]
    # steady state reached from rest (what the paper's runs from rest would settle on)
    a = {n: imp[n]["steady_marching_from_rest"]["x1_amplitude_mm"] for n in imp}
    r = {n: fri[n]["x1_rms_mm"] for n in fri}
    summary["conclusions"] = {
        "hunt_crossley_attenuates_more_than_linear_and_hertz": bool(
            a["hunt_crossley"] < a["kelvin_voigt"] and a["hunt_crossley"] < a["hertz"]
        ),
        "stribeck_attenuates_more_than_coulomb": bool(r["stribeck"] < r["coulomb"]),
        "lugre_attenuates_more_than_dahl": bool(r["lugre"] < r["dahl"]),
        "microscopic_vibrate_more_than_macroscopic": bool(
            min(r["dahl"], r["lugre"]) > max(r["coulomb"], r["stribeck"])
        ),
    }
    with open(os.path.join(out_dir, "summary.json"), "w") as fh:
        json.dump(summary, fh, indent=2)
    with open(os.path.join(out_dir, "amplitudes.csv"), "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(
            [
                "kind",
                "scene",
                "amplitude x1 [m]",
                "amplitude x2 - x1 [m]",
                "rms x1 [m]",
                "run time per simulated time [s/s]",
                "steps",
            ]
        )
        w.writerows(rows)
    return summary
