"""Work-precision report: error against run time for the seven laws in their paper scenes.

For each scene (1 s from rest; friction scenes under F0 = 10 N at 50 rad/s, N = 2 N, where
the absorber sticks and slips):

- **integration error**: every solver (diffrax Tsit5, Dopri5, Dopri8, Kvaerno5;
  scipy RK45, DOP853, Radau, LSODA on the same smoothed ODE in numpy) at rtol = 1e-3 … 1e-10
  (atol = rtol × 1e-3 m), against a tight solution of the *same* smoothed model (Dopri8,
  rtol 1e-12);
- **smoothing error**: the tight smoothed solution at several eps against the nonsmooth
  limit: the event-exact solutions of ``tests/references.py`` for Kelvin–Voigt and Coulomb
  (an *exact* reference), and for the other laws a converged reference at the smallest eps
  (marked *converged*: it shows the self-convergence of the smoothing, not an exact error);
- **steady-state amplitude**: shooting (Tsit5, Dopri8, Kvaerno5 at rtol 1e-5 … 1e-11; scipy
  fsolve on the solve_ivp period map with DOP853 and LSODA) against a tight
  shooting, plus the smoothing error of the amplitude and steady_state's defaults;
- **extreme cases** (tests/test_extreme.py): Tsit5 against Kvaerno5, and the automatic choice.

Errors are max |x1 - x1_ref| over 2001 samples, relative to max |x1_ref|.  Times are
after compilation (best of 2).  Writes ``work_precision_<scene>.png``, ``work_precision.md``
and ``work_precision.json`` to ``--out`` (plus per-part caches for ``--resume``).

    python scripts/work_precision.py --out work_precision [--quick] [--resume] [--part steady]
"""

from __future__ import annotations

import argparse
import inspect
import json
import os
import sys
import time

import jax
import numpy as np
from scipy.integrate import solve_ivp

import absorber_jax as aj

DEFAULT_RTOL = inspect.signature(aj.simulate).parameters["rtol"].default

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tests"))
import references as R  # noqa: E402

T1 = 1.0
TS = np.linspace(0.0, T1, 2001)
JAX_SOLVERS = ["tsit5", "dopri5", "dopri8", "kvaerno5"]
SCIPY_SOLVERS = ["RK45", "DOP853", "Radau", "LSODA"]
SCENES = ["kelvin_voigt", "hertz", "hunt_crossley", "coulomb", "stribeck_physical", "dahl",
          "lugre_physical"]
EPS = {"impact": [1e-5, 1e-6, 1e-7, 1e-8], "friction": [1e-3, 3e-4, 1e-4, 3e-5, 1e-5]}


def scene(name, eps=None):
    if name in aj.presets.IMPACT_SCENES:
        return aj.presets.impact(name, **({} if eps is None else {"eps": eps}))
    return aj.presets.friction(name, ramp_time=None, amplitude=10.0,
                               **({} if eps is None else {"eps": eps}))


def numpy_rhs(system, forcing):
    F0, w = float(forcing.amplitude), float(forcing.omega)
    if isinstance(system, aj.ImpactAbsorber):
        M, k, c, m, d = (float(getattr(system, a)) for a in ("M", "k", "c", "m", "gap"))
        law = system.contact
        K, C, e = float(law.stiffness), float(law.damping), float(law.eps)
        p = law.exponent
        hc = isinstance(law, aj.HuntCrossley)

        def wall(x, r):
            z = x / e
            delta = e * np.logaddexp(0.0, z)
            ddot = r * 0.5 * (1 + np.tanh(0.5 * z))
            return K * delta**p + C * (delta**1.5 if hc else 1.0) * ddot

        def f(t, y):
            x1, v1, x2, v2 = y
            u, du = x2 - x1, v2 - v1
            fc = wall(u - d, du) - wall(-u - d, -du)
            return [v1, (F0 * np.sin(w * t) - c * v1 - k * x1 + fc) / M, v2, -fc / m]

        return f
    m1, k1, c1, m2, k2, c2, N = (float(getattr(system, a)) for a in
                                 ("m1", "k1", "c1", "m2", "k2", "c2", "normal_force"))
    law = system.friction
    e = float(law.eps)

    def fr(V, z):
        if isinstance(law, aj.Coulomb):
            return float(law.mu) * N * np.tanh(V / e), 0.0
        if isinstance(law, aj.Stribeck):
            lvl = N * (float(law.mu_c) + (float(law.mu_s) - float(law.mu_c))
                       * np.exp(-((V / float(law.v_s)) ** 2)))
            return lvl * np.tanh(V / e), 0.0
        s0 = float(law.sigma0)
        if isinstance(law, aj.Dahl):
            zd = V - s0 * V * np.tanh(V / e) * z / (float(law.mu_c) * N)
            return s0 * z, zd
        g = N * (float(law.mu_c) + (float(law.mu_s) - float(law.mu_c))
                 * np.exp(-((V / float(law.v_s)) ** 2)))
        zd = V - s0 * V * np.tanh(V / e) * z / g
        return s0 * z + float(law.sigma1) * zd + float(law.sigma2) * V, zd

    def f(t, y):
        x1, v1, x2, v2 = y[:4]
        z = y[4] if len(y) > 4 else 0.0
        X, V = x1 - x2, v1 - v2
        fnl, zd = fr(V, z)
        a1 = (F0 * np.sin(w * t) - c1 * v1 - k1 * x1 - c2 * V - k2 * X - fnl) / m1
        a2 = (c2 * V + k2 * X + fnl) / m2
        out = [v1, a1, v2, a2]
        return out + [zd] if len(y) > 4 else out

    return f


def timed(fn, repeats=2):
    out = fn()
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return out, best


def rel_err(x, ref):
    return float(np.max(np.abs(np.asarray(x) - ref)) / np.max(np.abs(ref)))


def jax_run(system, forcing, solver, rtol):
    """One simulate run (rtol None: simulate's own defaults), best of 2 after compilation."""
    tol = {} if rtol is None else dict(rtol=rtol, atol=rtol * 1e-3)

    def go():
        tr = aj.simulate(system, forcing, T1, ts=TS, solver=solver, **tol, throw=False,
                         max_steps=400_000)
        jax.block_until_ready(tr.ys)
        return tr

    tr, t = timed(go)
    ok = int(tr.status) == 0
    return (np.asarray(tr.x1) if ok else None), t, int(tr.num_steps), int(tr.status)


def scipy_run(system, forcing, method, rtol, budget_s):
    f = numpy_rhs(system, forcing)
    y0 = np.zeros(system.num_states)
    t = time.perf_counter()
    sol = solve_ivp(f, (0.0, T1), y0, method=method, t_eval=TS, rtol=rtol, atol=rtol * 1e-3)
    dt = time.perf_counter() - t
    ok = sol.success and sol.y.shape[1] == TS.size
    return (sol.y[0] if ok else None), dt, int(sol.nfev), dt > budget_s


def reference(name, eps_list):
    """(nonsmooth reference x1, kind): event-exact where we have one, else converged."""
    if name == "kelvin_voigt":
        return R.impact_kelvin_voigt(1.0, 1e3, 0.1, 0.4, 1e-3, 400.0, 20.0, 2.0, 47.4, TS)[0], \
            "event-exact"
    if name == "coulomb":
        return R.friction_coulomb(1.0, 1e4, 0.0, 1.0, 1e4, 0.0, 0.5, 2.0, 10.0, 50.0, TS)[0], \
            "event-exact"
    system, forcing = scene(name, min(eps_list))
    tr = aj.simulate(system, forcing, T1, ts=TS, solver="kvaerno5" if name not in
                     aj.presets.IMPACT_SCENES else "dopri8", rtol=1e-12, atol=1e-15,
                     max_steps=2_000_000)
    return np.asarray(tr.x1), f"converged (eps = {min(eps_list):g})"


def run_trajectories(out, quick=False, resume=False):
    os.makedirs(out, exist_ok=True)
    tols = [1e-3, 1e-5, 1e-7, 1e-9] if quick else [1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9,
                                                   1e-10]
    scenes = SCENES[:2] if quick else SCENES
    results = {}
    for name in scenes:
        kind = "impact" if name in aj.presets.IMPACT_SCENES else "friction"
        cache = os.path.join(out, f"trajectory_{name}.json")
        if resume and os.path.exists(cache):
            with open(cache) as fh:
                results[name] = json.load(fh)
            print(f"== {name}: reused {cache}", flush=True)
            continue
        print(f"== {name}", flush=True)
        system, forcing = scene(name)
        tight = aj.simulate(system, forcing, T1, ts=TS, solver="dopri8" if kind == "impact"
                            else "kvaerno5", rtol=1e-12, atol=1e-15, max_steps=2_000_000)
        x_tight = np.asarray(tight.x1)
        rows = []
        for solver in JAX_SOLVERS:
            for rtol in tols:
                x, t, steps, status = jax_run(system, forcing, solver, rtol)
                rows.append(dict(lib="absorber_jax", solver=solver, rtol=rtol, seconds=t,
                                 steps=steps, status=status,
                                 error=None if x is None else rel_err(x, x_tight)))
                if x is None:
                    break  # failed (flagged status): tighter tolerances would fail too
        budget = 2.0 if quick else 20.0
        for method in SCIPY_SOLVERS:
            slow = False
            for rtol in tols:
                if slow or rtol < 1e-9:
                    continue  # scipy at 1e-10 and beyond, or after a run over budget: skipped
                x, t, nfev, slow = scipy_run(system, forcing, method, rtol, budget)
                rows.append(dict(lib="scipy", solver=method, rtol=rtol, seconds=t, steps=nfev,
                                 status=0 if x is not None else 2,
                                 error=None if x is None else rel_err(x, x_tight)))
        eps_list = EPS[kind][:3] if quick else EPS[kind]
        ref, ref_kind = reference(name, eps_list)
        smooth = []
        for eps in eps_list:
            s, f = scene(name, eps)
            tr = aj.simulate(s, f, T1, ts=TS, solver="dopri8" if kind == "impact" else "kvaerno5",
                             rtol=1e-12, atol=1e-15, max_steps=2_000_000)
            smooth.append(dict(eps=eps, error=rel_err(tr.x1, ref)))
        # the default settings of simulate (solver, rtol, atol), shown (not assumed)
        x_def, t_def, steps_def, st_def = jax_run(system, forcing, None, None)
        default = dict(solver=aj.choose_solver(system, forcing), rtol=DEFAULT_RTOL,
                       eps=float(getattr(system, "contact", getattr(system, "friction", None)).eps),
                       seconds=t_def, steps=steps_def,
                       integration_error=None if x_def is None else rel_err(x_def, x_tight),
                       total_error=None if x_def is None else rel_err(x_def, ref),
                       reference=ref_kind)
        results[name] = dict(rows=rows, smoothing=smooth, reference=ref_kind, default=default)
        plot(name, results[name], os.path.join(out, f"work_precision_{name}.png"))
        with open(cache, "w") as fh:
            json.dump(results[name], fh, indent=1)
        jax.clear_caches()  # one compile per (solver, rtol): free them per scene
        print(json.dumps(default), flush=True)
    return results


def run(out, quick=False, resume=False, parts=("trajectories", "steady", "extreme")):
    """The whole report; with ``resume``, parts and scenes already written are reused."""
    os.makedirs(out, exist_ok=True)
    allp = {}
    for part, fn in (("trajectories", run_trajectories), ("steady", run_steady),
                     ("extreme", run_extreme)):
        if part in parts:
            allp[part] = fn(out, quick, resume)
    with open(os.path.join(out, "work_precision.json"), "w") as fh:
        json.dump(allp, fh, indent=1)
    write_md(allp.get("trajectories", {}), os.path.join(out, "work_precision.md"),
             allp.get("steady"), allp.get("extreme"))
    return allp


STEADY_SOLVERS = ["tsit5", "dopri8", "kvaerno5"]
STEADY_TOLS = [1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11]


def steady_amplitude(system, forcing, **kw):
    def go():
        ss = aj.steady_state(system, forcing, floquet=False, **kw)
        jax.block_until_ready(ss.amplitude)
        return ss

    ss, t = timed(go, repeats=1)
    ok = int(ss.status) == 0
    return (float(ss.amplitude) if ok else None), t, int(ss.status)


def scipy_shooting(system, forcing, method, rtol):
    """Independent steady state: scipy fsolve on the solve_ivp period map (same smoothed
    model, public coordinates), amplitude = half peak-to-peak of x1 over 2048 samples."""
    from scipy.optimize import fsolve

    f = numpy_rhs(system, forcing)
    T = float(forcing.period)
    from absorber_jax._periodic.steady import state_scale

    # internal [x1, v1, u, w, z] scale -> public [x1, v1, x2, v2, z] (same magnitudes)
    scale = np.asarray(state_scale(system, forcing))
    x0 = np.asarray(system.to_public(aj.linear_guess(system, forcing)))

    def pmap(y):
        sol = solve_ivp(f, (0.0, T), y, method=method, rtol=rtol, atol=rtol * 1e-3)
        return sol.y[:, -1]

    t = time.perf_counter()
    y, info, ier, _ = fsolve(lambda q: (pmap(q * scale) - q * scale) / scale, x0 / scale,
                             full_output=True, xtol=1e-10)
    y = y * scale
    ts = np.linspace(0.0, T, 2049)
    sol = solve_ivp(f, (0.0, T), y, method=method, t_eval=ts, rtol=rtol, atol=rtol * 1e-3)
    dt = time.perf_counter() - t
    x1 = sol.y[0]
    return (0.5 * (x1.max() - x1.min()) if ier == 1 else None), dt, info["nfev"]


def run_steady(out, quick=False, resume=False):
    """Steady-state amplitude against run time: shooting at rtol 1e-5 ... 1e-11 for three
    solvers, against a tight shooting (rtol 1e-12, tol 1e-10) of the same smoothed model;
    the smoothing error of the amplitude against the smallest eps; scipy fsolve+solve_ivp
    shooting side by side; and the default settings of steady_state, shown."""
    results = {}
    for name in (SCENES[:2] if quick else SCENES):
        cache = os.path.join(out, f"steady_{name}.json")
        if resume and os.path.exists(cache):
            with open(cache) as fh:
                results[name] = json.load(fh)
            continue
        kind = "impact" if name in aj.presets.IMPACT_SCENES else "friction"
        print(f"== steady {name}", flush=True)
        system, forcing = scene(name)
        tight = dict(rtol=1e-12, atol=1e-12, tol=1e-10, max_steps=2_000_000,
                     solver="dopri8" if kind == "impact" else "kvaerno5")
        a_tight, t_tight, st = steady_amplitude(system, forcing, **tight)
        print(f"  tight: {t_tight:.2f} s, status {st}", flush=True)
        rows = []
        for solver in STEADY_SOLVERS:
            for rtol in (STEADY_TOLS[::2] if quick else STEADY_TOLS):
                a, t, status = steady_amplitude(system, forcing, solver=solver, rtol=rtol,
                                                atol=rtol)
                print(f"  {solver} rtol {rtol:g}: {t:.2f} s, status {status}", flush=True)
                rows.append(dict(lib="absorber_jax", solver=solver, rtol=rtol, seconds=t,
                                 status=status, amplitude=a,
                                 error=None if a is None else abs(a - a_tight) / a_tight))
        for method in ["DOP853", "LSODA"]:  # RK45 and Radau: in the trajectory part only
            for rtol in ([1e-6, 1e-9] if quick else [1e-6, 1e-8, 1e-10]):
                a, t, nfev = scipy_shooting(system, forcing, method, rtol)
                print(f"  scipy {method} rtol {rtol:g}: {t:.2f} s", flush=True)
                rows.append(dict(lib="scipy", solver=method, rtol=rtol, seconds=t, status=0
                                 if a is not None else 2, amplitude=a, steps=int(nfev),
                                 error=None if a is None else abs(a - a_tight) / a_tight))
        eps_list = EPS[kind][:3] if quick else EPS[kind]
        amps = []
        for eps in eps_list:
            s2, f2 = scene(name, eps)
            amps.append(steady_amplitude(s2, f2, **tight)[0])
        ref = amps[-1]
        smooth = [dict(eps=e, amplitude=a, error=None if a is None or ref is None
                       else abs(a - ref) / ref) for e, a in zip(eps_list, amps)]
        a_def, t_def, st_def = steady_amplitude(system, forcing)
        default = dict(solver=aj.choose_solver(system, forcing), rtol=1e-9, seconds=t_def,
                       status=st_def, amplitude=a_def,
                       integration_error=None if a_def is None else abs(a_def - a_tight)
                       / a_tight,
                       total_error=None if a_def is None or ref is None else
                       abs(a_def - ref) / ref,
                       reference=f"converged (eps = {min(eps_list):g}, rtol 1e-12)")
        results[name] = dict(rows=rows, smoothing=smooth, tight=a_tight, default=default,
                             omega=float(forcing.omega), amplitude_force=float(forcing.amplitude))
        with open(cache, "w") as fh:
            json.dump(results[name], fh, indent=1)
        jax.clear_caches()  # one compile per (solver, rtol): free them per scene
        print(json.dumps(default), flush=True)
    plot_steady(results, os.path.join(out, "work_precision_steady.png"))
    return results


def run_extreme(out, quick=False, resume=False):
    """Explicit (Tsit5) against implicit (Kvaerno5) on the extreme cases of
    tests/test_extreme.py: 3 forcing periods from rest, steps, time, status; the automatic
    choice; and the steady state with the default budget."""
    cache = os.path.join(out, "extreme.json")
    if resume and os.path.exists(cache):
        with open(cache) as fh:
            return json.load(fh)
    import test_extreme as X

    results = {}
    for name, (system, F0, omega, _) in X.CASES.items():
        print(f"== extreme {name}", flush=True)
        forcing = aj.Harmonic(amplitude=F0, omega=omega)
        T = 2 * np.pi / omega
        row = dict(auto=aj.choose_solver(system, forcing),
                   rate_times_period=float(system.stiffness_rate()) * T)
        for solver in ("tsit5", "kvaerno5"):
            def go(system=system, forcing=forcing, T=T, solver=solver):
                tr = aj.simulate(system, forcing, 3 * T, solver=solver, throw=False,
                                 max_steps=100_000 if quick else 1_000_000)
                jax.block_until_ready(tr.ys)
                return tr

            tr, t = timed(go, repeats=1)
            row[solver] = dict(status=aj.describe(tr.status), steps=int(tr.num_steps),
                               seconds=t, x1_max_mm=float(np.max(np.abs(tr.x1))) * 1e3
                               if int(tr.status) == 0 else None)
        t0 = time.perf_counter()
        ss = aj.steady_state(system, forcing, **({"max_steps": 20_000} if quick else {}))
        row["steady"] = dict(status=aj.describe(ss.status), seconds=time.perf_counter() - t0,
                             amplitude_mm=float(ss.amplitude) * 1e3 if ss.ok else None)
        print(json.dumps(row), flush=True)
        results[name] = row
        jax.clear_caches()  # one compile per (solver, rtol): free them per scene
    with open(cache, "w") as fh:
        json.dump(results, fh, indent=1)
    return results


def plot(name, res, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(1, 2, figsize=(12, 4.5))
    markers = dict(zip(JAX_SOLVERS + SCIPY_SOLVERS, "os^Dvx+*1"))
    for key in JAX_SOLVERS + SCIPY_SOLVERS:
        pts = [(r["seconds"], r["error"]) for r in res["rows"] if r["solver"] == key and
               r["error"] is not None and r["error"] > 0]
        if pts:
            s, e = zip(*pts)
            lib = "scipy " if key in SCIPY_SOLVERS else ""
            axs[0].loglog(s, e, marker=markers[key], ls="-" if lib == "" else "--",
                          label=lib + key)
    failed = sorted({r["solver"] for r in res["rows"] if r["error"] is None})
    axs[0].set(xlabel="run time [s] (after compilation)", ylabel="integration error (rel.)",
               title=f"{name}: integration error" + (f"\nfailed: {', '.join(failed)}"
                                                     if failed else ""))
    axs[0].legend(fontsize=7)
    e = [r["eps"] for r in res["smoothing"]]
    axs[1].loglog(e, [r["error"] for r in res["smoothing"]], "o-")
    axs[1].set(xlabel="eps", ylabel="smoothing error (rel.)",
               title=f"smoothing error vs {res['reference']} reference")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_steady(results, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(results)
    cols = min(n, 4)
    rows_ = -(-n // cols)
    fig, axs = plt.subplots(rows_, cols, figsize=(4 * cols, 3.6 * rows_), squeeze=False)
    for ax, (name, res) in zip(axs.flat, results.items()):
        for key in STEADY_SOLVERS + SCIPY_SOLVERS:
            pts = [(r["seconds"], max(r["error"], 1e-16)) for r in res["rows"]
                   if r["solver"] == key and r["error"] is not None]
            if pts:
                t, e = zip(*pts)
                ax.loglog(t, e, marker="o" if key in STEADY_SOLVERS else "x",
                          ls="-" if key in STEADY_SOLVERS else "--",
                          label=("" if key in STEADY_SOLVERS else "scipy ") + key)
        d = res["default"]
        if d["integration_error"] is not None:
            ax.loglog([d["seconds"]], [max(d["integration_error"], 1e-16)], "k*", ms=12,
                      label="default")
        ax.set(title=f"{name} ({res['omega']:g} rad/s)", xlabel="run time [s]",
               ylabel="amplitude error (rel.)")
        ax.legend(fontsize=6)
    for ax in list(axs.flat)[n:]:
        ax.axis("off")
    fig.suptitle("Steady-state amplitude: error against run time (shooting)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def write_md(results, path, steady=None, extreme=None):
    lines = ["# Work-precision report", "",
             "Errors: max |x1 - ref| / max |ref| over 1 s (2001 samples). Integration error: "
             "against a tight solution (rtol 1e-12) of the same smoothed model. Smoothing "
             "error: tight smoothed solution against the nonsmooth reference (event-exact for "
             "Kelvin–Voigt and Coulomb, converged at the smallest eps for the others).", "",
             "## Defaults (shown, not assumed)", "",
             "| scene | solver | rtol | eps | time [s] | steps | integration error | "
             "total error | reference |", "|---|---|---|---|---|---|---|---|---|"]
    for name, r in results.items():
        d = r["default"]
        fmt = lambda v: "failed" if v is None else f"{v:.1e}"  # noqa: E731
        lines.append(f"| {name} | {d['solver']} | {d['rtol']:g} | {d['eps']:g} | "
                     f"{d['seconds']:.3f} | {d['steps']} | {fmt(d['integration_error'])} | "
                     f"{fmt(d['total_error'])} | {d['reference']} |")
    lines += ["", "## Fastest run reaching 1e-6 integration error", "",
              "| scene | " + " | ".join(JAX_SOLVERS + SCIPY_SOLVERS) + " |",
              "|---|" + "---|" * (len(JAX_SOLVERS) + len(SCIPY_SOLVERS))]
    for name, r in results.items():
        cells = []
        for key in JAX_SOLVERS + SCIPY_SOLVERS:
            ok = [x for x in r["rows"] if x["solver"] == key and x["error"] is not None
                  and x["error"] <= 1e-6]
            cells.append(f"{min(x['seconds'] for x in ok):.3f} s" if ok else "—")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    lines += ["", "## Smoothing error", "", "| scene | reference | eps: error |", "|---|---|---|"]
    for name, r in results.items():
        lines.append(f"| {name} | {r['reference']} | " + ", ".join(
            f"{s['eps']:g}: {s['error']:.1e}" for s in r["smoothing"]) + " |")
    fmt = lambda v: "—" if v is None else f"{v:.1e}"  # noqa: E731
    if steady:
        lines += ["", "## Steady-state amplitude (shooting)", "",
                  "Amplitude of x1 (half peak-to-peak over one period) from `steady_state`, "
                  "against a tight shooting (rtol 1e-12, tol 1e-10) of the same smoothed "
                  "model (integration error), and against the tight solve at the smallest "
                  "eps (total error; a *converged* reference, no event-exact periodic orbit "
                  "is computed here). Times include the Newton iterations, not compilation.",
                  "", "### Defaults of steady_state (rtol 1e-9, tol 1e-6), shown", "",
                  "| scene | ω [rad/s] | solver | amplitude [mm] | time [s] | "
                  "integration error | total error |", "|---|---|---|---|---|---|---|"]
        for name, r in steady.items():
            d = r["default"]
            amp = "failed" if d["amplitude"] is None else f"{d['amplitude'] * 1e3:.5f}"
            lines.append(f"| {name} | {r['omega']:g} | {d['solver']} | {amp} | "
                         f"{d['seconds']:.2f} | {fmt(d['integration_error'])} | "
                         f"{fmt(d['total_error'])} |")
        keys = sorted({x["solver"] for r in steady.values() for x in r["rows"]},
                      key=lambda k: (k not in STEADY_SOLVERS, k))
        lines += ["", "### Fastest run reaching 1e-6 amplitude error", "",
                  "| scene | " + " | ".join(keys) + " |", "|---|" + "---|" * len(keys)]
        for name, r in steady.items():
            cells = []
            for key in keys:
                ok = [x for x in r["rows"] if x["solver"] == key and x["error"] is not None
                      and x["error"] <= 1e-6]
                cells.append(f"{min(x['seconds'] for x in ok):.2f} s" if ok else "—")
            lines.append(f"| {name} | " + " | ".join(cells) + " |")
        lines += ["", "### Smoothing error of the amplitude", "", "| scene | eps: error |",
                  "|---|---|"]
        for name, r in steady.items():
            lines.append(f"| {name} | " + ", ".join(
                f"{x['eps']:g}: {fmt(x['error'])}" for x in r["smoothing"][:-1]) + " |")
    if extreme:
        lines += ["", "## Extreme cases: explicit against implicit", "",
                  "3 forcing periods from rest with each solver (rtol 1e-8), and the steady "
                  "state with the automatic choice.", "",
                  "| case | λT | auto | Tsit5 steps / time | Kvaerno5 steps / time | "
                  "steady state |", "|---|---|---|---|---|---|"]
        for name, r in extreme.items():
            def cell(c):
                if c["status"] != aj.describe(0):
                    return f"{c['status'].split(' (')[0]} ({c['steps']} steps, " \
                           f"{c['seconds']:.1f} s)"
                return f"{c['steps']} / {c['seconds']:.2f} s"
            st = r["steady"]
            ss = (f"{st['amplitude_mm']:.4g} mm" if st["amplitude_mm"] is not None
                  else st["status"].split(" (")[0]) + f" ({st['seconds']:.1f} s)"
            lines.append(f"| {name} | {r['rate_times_period']:.1e} | {r['auto']} | "
                         f"{cell(r['tsit5'])} | {cell(r['kvaerno5'])} | {ss} |")
    lines.append("")
    with open(path, "w") as fh:
        fh.write("\n".join(lines))


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="work_precision")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--resume", action="store_true",
                    help="reuse the per-scene results already written to --out")
    ap.add_argument("--part", action="append", choices=["trajectories", "steady", "extreme"],
                    help="run only this part (repeatable; default all)")
    a = ap.parse_args()
    run(a.out, a.quick, a.resume, tuple(a.part or ("trajectories", "steady", "extreme")))
