"""Command line: ``absorber-jax`` (or ``python -m absorber_jax``)."""

from __future__ import annotations

import argparse
import json
import sys


def _parse_sets(items):
    out = {}
    for item in items or []:
        if "=" not in item:
            raise SystemExit(f"--set expects field=value, got {item!r}")
        k, v = item.split("=", 1)
        out[k.strip()] = float(v)
    return out


def cmd_reproduce(args):
    from .paper import reproduce_paper

    summary = reproduce_paper(args.out, quick=args.quick)
    print(json.dumps(summary["conclusions"], indent=2))
    print(f"figures, summary.json and amplitudes.csv written to {args.out}")


def cmd_simulate(args):
    import csv
    import os

    import numpy as np

    from .. import presets
    from .._integration.simulate import simulate

    system, forcing = presets.scene(args.scene)
    sets = _parse_sets(args.set)
    if sets:
        from .._systems.params import with_params

        system = with_params(system, sets)
    tr = simulate(system, forcing, args.t1, solver=args.solver)
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    cols = {"t": tr.ts, "x1": tr.x1, "v1": tr.v1, "x2": tr.x2, "v2": tr.v2,
            "coupling_force": tr.coupling_force}
    if tr.friction_force is not None:
        cols.update(friction_force=tr.friction_force, force_ratio=tr.force_ratio,
                    regime=tr.regime)
    with open(args.out, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(list(cols))
        w.writerows(np.stack([np.asarray(c, dtype=float) for c in cols.values()], axis=1))
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        f, ax = plt.subplots(figsize=(8, 4))
        ax.plot(np.asarray(tr.ts), np.asarray(tr.x1) * 1e3, lw=0.7, label="x1 (primary)")
        ax.plot(np.asarray(tr.ts), np.asarray(tr.x2) * 1e3, lw=0.7, label="x2 (absorber)")
        ax.set(xlabel="t [s]", ylabel="displacement [mm]", title=args.scene)
        ax.legend()
        f.tight_layout()
        f.savefig(args.plot, dpi=110)
    print(f"{args.scene}: {int(tr.num_steps)} steps with {tr.solver}; x1 amplitude "
          f"(last 10 periods) {tr.amplitude() * 1e3:.4f} mm -> {args.out}")


def _steady_scene(args):
    """The scene named by ``--scene`` under a constant harmonic force, with ``--set`` applied."""
    from .. import presets
    from .._systems.params import with_params

    kw = {"ramp_time": None} if args.scene in presets.FRICTION_SCENES else {}
    system, forcing = presets.scene(args.scene, **kw)
    sets = _parse_sets(args.set)
    return (with_params(system, sets) if sets else system), forcing


def _parse_range(text, what):
    try:
        lo, hi, n = text.split(":")
        lo, hi, n = float(lo), float(hi), int(n)
    except ValueError:
        raise SystemExit(f"{what} expects LO:HI:N (e.g. 30:70:64), got {text!r}") from None
    if not (0 < lo < hi) or n < 1:
        raise ValueError(f"{what} must satisfy 0 < LO < HI and N >= 1, got {text!r}")
    return lo, hi, n


def cmd_sweep(args):
    import json
    import os
    import time

    import numpy as np

    from .._periodic.sweep import frequency_response
    from .plots import plot_frequency_response

    lo, hi, n = _parse_range(args.omega, "--omega")
    system, forcing = _steady_scene(args)
    amplitude = args.amplitude if args.amplitude is not None else float(forcing.amplitude)
    om = np.linspace(lo, hi, n)
    t = time.perf_counter()
    out = frequency_response(system, om, amplitude=amplitude, method=args.method,
                             direction=args.direction, chunk_size=args.chunk, progress=True)
    elapsed = time.perf_counter() - t
    frfs = list(out) if isinstance(out, tuple) else [out]
    for d in (os.path.dirname(os.path.abspath(p)) for p in [args.out] + [args.plot or args.out]):
        os.makedirs(d, exist_ok=True)
    if len(frfs) == 1:
        frfs[0].to_csv(args.out)
    else:
        base, ext = os.path.splitext(args.out)
        for f in frfs:
            f.to_csv(f"{base}_{f.direction}{ext}")
    if args.plot:
        plot_frequency_response(frfs, args.plot,
                                title=f"{args.scene}, F0 = {amplitude:g} N ({args.method})")
    failed = sum(int((f.status != 0).sum()) for f in frfs)
    print(json.dumps({"scene": args.scene, "points": n * len(frfs), "failed": failed,
                      "seconds": round(elapsed, 3), "csv": args.out, "png": args.plot}))


def cmd_tune(args):
    import csv
    import json
    import os

    import numpy as np

    from .._design.objectives import BY_NAME
    from .._design.tune import plot_tuning, tune

    lo, hi, _ = _parse_range(args.band + ":1", "--band")
    system, forcing = _steady_scene(args)
    bounds = {}
    for item in args.bounds or []:
        name, rng = item.split("=", 1)
        b_lo, b_hi = (float(x) for x in rng.split(":"))
        bounds[name.strip()] = (b_lo, b_hi)
    amplitude = args.amplitude if args.amplitude is not None else float(forcing.amplitude)
    params = [p.strip() for p in args.params.split(",") if p.strip()]
    objective = BY_NAME[args.objective](n_freq=args.n_freq)
    tuned, hist = tune(system, params, (lo, hi), amplitude=amplitude, objective=objective,
                       steps=args.steps, bounds=bounds, progress=True,
                       confirm=not args.no_confirm)
    os.makedirs(args.out, exist_ok=True)
    plot_tuning(system, tuned, hist, os.path.join(args.out, "tuning.png"),
                title=f"{args.scene}: {', '.join(params)} over {lo:g}–{hi:g} rad/s")
    with open(os.path.join(args.out, "curves.csv"), "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["omega", "amplitude_before", "amplitude_after"])
        w.writerows(zip(hist["omegas"], hist["amplitude_before"], hist["amplitude_after"]))
    summary = {"scene": args.scene, "params": params, "band": [lo, hi],
               "objective": args.objective, "start": {k: v[0] for k, v in hist["params"].items()},
               "tuned": hist["best"],
               "peak_before_mm": float(np.max(hist["amplitude_before"]) * 1e3),
               "peak_after_mm": float(np.max(hist["amplitude_after"]) * 1e3),
               "history": {k: hist[k] for k in ("objective", "grad_norm", "failed", "nonsmooth",
                                                "peak_bias")},
               "history_params": hist["params"]}
    if "confirm" in hist:
        c = hist["confirm"]
        summary["marching_check"] = {
            "omegas": c["omegas"].tolist(), "before_mm": (c["before"] * 1e3).tolist(),
            "after_mm": (c["after"] * 1e3).tolist(), "status_before": c["status_before"].tolist(),
            "status_after": c["status_after"].tolist()}
    if "settles_on" in hist:
        summary["settles_on"] = hist["settles_on"]
    if "robust" in hist:
        summary["robust"] = hist["robust"]
        summary["robust_rounds"] = [{k: v for k, v in r.items() if k != "found"}
                                    | {"found": [{k: v for k, v in f.items() if k != "state"}
                                                 for f in r["found"]]}
                                    for r in hist["rounds"]]
    with open(os.path.join(args.out, "tuning.json"), "w") as fh:
        json.dump(summary, fh, indent=2)
    print(json.dumps({k: summary[k] for k in ("tuned", "peak_before_mm", "peak_after_mm")}))


def _peak(omegas, values, ok):
    """``(peak, omega)`` of ``values`` over the successful points (``None`` if none)."""
    import numpy as np

    v = np.where(ok, np.asarray(values, dtype=float), -np.inf)
    if not np.isfinite(v).any():
        return None, None
    i = int(np.argmax(v))
    return float(v[i]), float(omegas[i])


def _plot_scene_dofs(frfs, dof_names, path, title):
    """Amplitude of every structural degree of freedom against frequency: filled markers
    stable, open markers unstable, red crosses failed points."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fig, ax = plt.subplots(figsize=(8, 4.5))
    colors = plt.get_cmap("tab10")
    styles = {"parallel": "o", "up": "^", "down": "v"}
    any_failed = any_unstable = False
    for frf in frfs:
        om = np.asarray(frf.omegas)
        ok = np.asarray(frf.status) == 0
        st = np.asarray(frf.stable).astype(bool)
        mk = styles.get(frf.direction, "o")
        tag = "" if len(frfs) == 1 else f" ({frf.direction})"
        for j, name in enumerate(dof_names):
            a = np.asarray(frf.dof(name, "amplitude"), dtype=float)
            c = colors(j % 10)
            ax.plot(om[ok], a[ok], "-", lw=0.8, color=c, label=f"{name}{tag}")
            ax.plot(om[ok & st], a[ok & st], mk, ms=3, color=c)
            if (ok & ~st).any():
                any_unstable = True
                ax.plot(om[ok & ~st], a[ok & ~st], mk, ms=5, mfc="none", color=c)
        if (~ok).any():
            any_failed = True
            ax.plot(om[~ok], np.zeros((~ok).sum()), "x", color="red", clip_on=False)
    if any_unstable:
        ax.plot([], [], "o", mfc="none", color="0.3", label="unstable (open markers)")
    if any_failed:
        ax.plot([], [], "x", color="red", label="failed")
    ax.set_yscale("log")
    ax.set(xlabel="ω [rad/s]", ylabel="amplitude (half peak-to-peak) [m or rad]", title=title)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def cmd_scene(args):
    import csv
    import json
    import os
    import time

    import jax
    import numpy as np

    from .._integration.simulate import simulate
    from .._periodic.sweep import frequency_response
    from .._systems.forcing import Harmonic
    from .._systems.params import get_param, replace_params
    from .scene import load_scene

    t_start = time.perf_counter()
    system, settings = load_scene(args.file)
    sets = _parse_sets(args.set)
    if sets:
        system = replace_params(system, sets)
    if args.omega is not None:
        lo, hi, n = _parse_range(args.omega, "--omega")
        omegas = np.linspace(lo, hi, n)
    elif settings.omegas is not None:
        omegas = settings.omegas
    else:
        raise ValueError(f"{args.file}: no [sweep] in the scene file; give it one "
                         f"(omegas = {{start, stop, num}}) or pass --omega LO:HI:N")
    amplitude = args.amplitude if args.amplitude is not None else settings.amplitude
    direction = args.direction or settings.direction
    method = args.method or settings.method
    title = settings.title or os.path.splitext(os.path.basename(args.file))[0]
    os.makedirs(args.out, exist_ok=True)
    t_loaded = time.perf_counter()
    out = frequency_response(system, omegas, amplitude=amplitude, method=method,
                             direction=direction, chunk_size=args.chunk, progress=args.progress)
    t_swept = time.perf_counter()
    frfs = list(out) if isinstance(out, tuple) else [out]
    csvs = []
    for f in frfs:
        name = ("frequency_response.csv" if len(frfs) == 1
                else f"frequency_response_{f.direction}.csv")
        f.to_csv(os.path.join(args.out, name))
        csvs.append(name)
    dof_names = list(system.structure.dof_names)
    _plot_scene_dofs(frfs, dof_names, os.path.join(args.out, "frequency_response.png"),
                     f"{title}\nF0 = {amplitude:g} ({method}, {direction})")

    # summary: the observable's peak, every output's peak, failures (over all directions)
    best, per_dof, failures, unstable = None, {}, [], 0
    for f in frfs:
        om = np.asarray(f.omegas)
        ok = np.asarray(f.status) == 0
        stable = np.asarray(f.stable).astype(bool)
        unstable += int((ok & ~stable).sum())
        a, w = _peak(om, f.amplitude, ok)
        if a is not None and (best is None or a > best["amplitude"]):
            i = int(np.flatnonzero(om == w)[0])
            best = {"amplitude": a, "omega": w, "stable": bool(stable[i]),
                    "direction": f.direction}
        for name in f.dof_names:
            a, w = _peak(om, f.dof(name, "amplitude"), ok)
            if a is not None and (name not in per_dof or a > per_dof[name]["amplitude"]):
                per_dof[name] = {"amplitude": a, "omega": w, "direction": f.direction}
        failures += [{"direction": f.direction, "omega": float(om[i[-1]]), "status": text}
                     for i, text in f.failures()]
    params = {k: float(np.asarray(get_param(system, k))) for k in system.parameter_names()}
    summary = {
        "scene": os.path.abspath(args.file), "title": settings.title,
        "dofs": dof_names, "outputs": list(system.output_names),
        "elements": list(system.element_names), "parameters": params, "set": sets,
        "amplitude": amplitude, "method": method, "direction": direction,
        "omegas": {"start": float(omegas[0]), "stop": float(omegas[-1]), "num": len(omegas)},
        "observable_peak": best, "dof_peaks": per_dof,
        "points": len(omegas) * len(frfs), "failed": len(failures), "failures": failures,
        "unstable": unstable, "csv": csvs, "png": "frequency_response.png",
        "timing_s": {"load": round(t_loaded - t_start, 3), "sweep": round(t_swept - t_loaded, 3)},
    }
    if args.simulate:
        omega = settings.simulate_omega or (best["omega"] if best else float(omegas[0]))
        periods = settings.simulate_periods
        t1 = periods * 2 * np.pi / omega
        t = time.perf_counter()
        tr = simulate(system, Harmonic(amplitude=amplitude, omega=omega), t1)
        ys = jax.vmap(system.outputs)(jax.vmap(system.to_internal)(tr.ys))
        ys, ts = np.asarray(ys), np.asarray(tr.ts)
        forces = np.asarray(tr.coupling_force).reshape(len(ts), -1)
        with open(os.path.join(args.out, "trajectory.csv"), "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["t", *system.output_names,
                        *(f"force[{e}]" for e in system.element_names)])
            w.writerows(np.column_stack([ts, ys, forces]).tolist())
        last = ts >= ts[-1] - 10 * 2 * np.pi / omega
        amps = {nm: float(0.5 * np.ptp(ys[last, j]))
                for j, nm in enumerate(system.output_names)}
        summary["simulation"] = {"omega": omega, "t1": t1, "periods": periods,
                                 "solver": tr.solver, "steps": int(tr.num_steps),
                                 "amplitude_last_10_periods": amps, "csv": "trajectory.csv",
                                 "png": "trajectory.png"}
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(8, 4))
        for j, nm in enumerate(dof_names):
            ax.plot(ts, ys[:, j], lw=0.7, label=nm)
        ax.set(xlabel="t [s]", ylabel="displacement [m or rad]",
               title=f"{title}\nfrom rest at ω = {omega:.4g} rad/s")
        ax.legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(os.path.join(args.out, "trajectory.png"), dpi=110)
        plt.close(fig)
        summary["timing_s"]["simulate"] = round(time.perf_counter() - t, 3)
    summary["timing_s"]["total"] = round(time.perf_counter() - t_start, 3)
    with open(os.path.join(args.out, "summary.json"), "w") as fh:
        json.dump(summary, fh, indent=2)
    pk = (f"peak {best['amplitude']:.4g} at ω = {best['omega']:.4g} rad/s"
          + ("" if best["stable"] else " (unstable)")) if best else "no successful point"
    print(f"{title}: {summary['points']} points, {len(failures)} failed, {unstable} unstable; "
          f"observable {pk}; sweep {summary['timing_s']['sweep']:.1f} s -> {args.out}")
    for nm, v in per_dof.items():
        print(f"  {nm:>12s}: peak {v['amplitude']:.4g} at ω = {v['omega']:.4g} rad/s")
    if "simulation" in summary:
        s = summary["simulation"]
        print(f"  simulated {s['periods']} periods at ω = {s['omega']:.4g} rad/s "
              f"({s['steps']} steps, {s['solver']}) -> trajectory.csv")


def cmd_work_precision(args):
    import os
    import runpy
    import sys

    script = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scripts",
                          "work_precision.py")
    if not os.path.exists(script):
        raise ValueError("work-precision needs the repository checkout (scripts/ and tests/ "
                         "with the event-exact references): install with `pip install -e .` "
                         "from a clone")
    sys.argv = [script, "--out", args.out] + (["--quick"] if args.quick else []) + \
        (["--resume"] if args.resume else [])
    runpy.run_path(script, run_name="__main__")


def _parse_bounds(text, flag):
    try:
        lo, hi = (float(v) for v in text.split(":"))
    except ValueError:
        raise ValueError(f"{flag} expects LO:HI, got {text!r}") from None
    return lo, hi


def cmd_continue(args):
    """Continuation of a branch (and, with --switch, the period-2n branches born at its
    period doublings): CSV per branch, JSON summary, PNG."""
    import json
    import os
    import time

    from .._continuation.continuation import PseudoArclength, continuation
    from .._systems.forcing import Harmonic
    from .plots import plot_branches

    t0 = time.perf_counter()
    system, amplitude, title, sets = _load_system(args)
    lo, hi = _parse_bounds(args.bounds, "--bounds")
    omega = args.omega
    if args.parameter == "omega":
        start = args.start if args.start is not None else (lo if args.direction == "up" else hi)
        omega = start
    elif args.start is not None:
        if args.parameter == "amplitude":
            amplitude = args.start
        else:
            from .._systems.params import replace_params

            system = replace_params(system, {args.parameter: args.start})
    if omega is None:
        raise ValueError("--omega is required when continuing in a parameter other than omega")
    forcing = Harmonic(amplitude=amplitude, omega=omega)
    method = PseudoArclength(step=args.step, max_step=max(args.step, args.max_step),
                             max_points=args.max_points)
    os.makedirs(args.out, exist_ok=True)
    branches = [continuation(system, forcing, args.parameter, bounds=(lo, hi), method=method,
                             n=args.n, direction=args.direction, progress=args.progress)]
    if args.switch:
        for b in list(branches[0].of_kind("period_doubling")):
            branches.append(continuation(system, forcing, args.parameter, bounds=(lo, hi),
                                         method=method, start=b, progress=args.progress))
    names = []
    for k, br in enumerate(branches):
        name = "branch.csv" if k == 0 else f"branch_switched_{k}_period{br.period_multiple}.csv"
        br.to_csv(os.path.join(args.out, name))
        names.append(name)
    plot_branches(branches, os.path.join(args.out, "branches.png"), scale=1.0,
                  title=f"{title}: continuation in {args.parameter} (F0 = {amplitude:g})")
    summary = {"scene": args.file or args.scene, "parameter": args.parameter,
               "bounds": [lo, hi], "amplitude": amplitude, "set": sets,
               "branches": [dict(br.summary(), csv=n) for br, n in zip(branches, names)],
               "time_s": time.perf_counter() - t0}
    with open(os.path.join(args.out, "summary.json"), "w") as fh:
        json.dump(summary, fh, indent=2)
    for br in branches:
        print(f"period-{br.period_multiple} branch: {len(br)} points, {br.termination}; "
              + ", ".join(f"{b.kind} at {b.value:.6g}" for b in br.bifurcations))
    print(f"CSV, summary.json and branches.png written to {args.out} "
          f"({summary['time_s']:.1f} s)")


def _load_system(args):
    """(system, F0, title, sets) from --file (a scene file) or --scene (a preset), with the
    --set replacements and --amplitude applied."""
    import os

    if args.file:
        from .scene import load_scene

        system, settings = load_scene(args.file)
        amplitude = settings.amplitude
        title = settings.title or os.path.splitext(os.path.basename(args.file))[0]
    else:
        from .. import presets

        system, forcing = presets.scene(args.scene)
        amplitude, title = float(forcing.amplitude), args.scene
    sets = _parse_sets(args.set)
    if sets:
        from .._systems.params import replace_params

        system = replace_params(system, sets)
    if args.amplitude is not None:
        amplitude = args.amplitude
    return system, amplitude, title, sets


def cmd_attractors(args):
    """Attractor map at one frequency (--omega W) or a stroboscopic bifurcation diagram
    over a range (--omega LO:HI:N): JSON summary, CSV per initial state, PNG."""
    import csv
    import json
    import os
    import time

    import numpy as np

    from .._periodic.attractors import attractors, bifurcation_diagram
    from .._systems.forcing import Harmonic
    from .plots import plot_bifurcation_diagram

    t0 = time.perf_counter()
    system, amplitude, title, sets = _load_system(args)
    opts = dict(samples=args.samples, n_max=args.n_max, max_periods=args.max_periods,
                give_up=args.give_up, window=args.window, seed=args.seed)
    os.makedirs(args.out, exist_ok=True)
    if ":" in args.omega:
        lo, hi, n = _parse_range(args.omega, "--omega")
        omegas = np.linspace(lo, hi, n)
        maps = bifurcation_diagram(system, Harmonic(amplitude=amplitude, omega=lo), omegas,
                                   progress=args.progress, **opts)
    else:
        w = float(args.omega)
        maps = [attractors(system, Harmonic(amplitude=amplitude, omega=w), **opts)]
    with open(os.path.join(args.out, "attractors.csv"), "w", newline="") as fh:
        wr = csv.writer(fh)
        wr.writerow(["omega", "sample", *[f"y0[{s}]" for s in system.state_names],
                     "attractor", "periodic", "period_multiple", "amplitude", "rms", "peak",
                     "spread", "impacts_per_period", "lyapunov_per_s", "marching_status"])
        for m in maps:
            for k in range(m.label.shape[0]):
                lab = int(m.label[k])
                a = m.attractors[lab] if lab >= 0 else None
                wr.writerow([m.omega, k, *m.initial_states[k], lab,
                             int(a.periodic) if a else "", a.period_multiple if a else "",
                             m.amplitude[k], m.rms[k], m.peak[k], m.spread[k],
                             m.impacts[k], m.lyapunov[k], int(m.steady.status[k])])
    summary = {"scene": args.file or args.scene, "F0": amplitude, "set": sets, **opts,
               "maps": [m.summary() for m in maps], "time_s": time.perf_counter() - t0}
    with open(os.path.join(args.out, "summary.json"), "w") as fh:
        json.dump(summary, fh, indent=2)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if len(maps) > 1:
        plot_bifurcation_diagram(maps, os.path.join(args.out, "bifurcation_diagram.png"),
                                 title=f"{title}: stroboscopic bifurcation diagram "
                                       f"(F0 = {amplitude:g})")
    else:
        m = maps[0]
        fig, ax = plt.subplots(figsize=(6, 5))
        names = system.state_names
        for i, a in enumerate(m.attractors):
            sel = m.label == i
            kind = f"period-{a.period_multiple}" if a.periodic else a.kind
            ax.plot(m.initial_states[sel, 0], m.initial_states[sel, 1], "o", ms=5,
                    label=f"{kind}: amplitude {a.amplitude:.4g}, peak {a.peak:.4g}, "
                          f"{a.impacts:.3g} impacts/period ({100 * a.share:.0f} %)")
        ax.set(xlabel=f"{names[0]}(0)", ylabel=f"{names[1]}(0)",
               title=f"{title}: attractors at ω = {m.omega:g} rad/s")
        ax.legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(os.path.join(args.out, "attractors.png"), dpi=110)
        plt.close(fig)
    for m in maps:
        print(f"ω = {m.omega:g}: " + "; ".join(
            (f"period-{a.period_multiple}" if a.periodic else "not periodic")
            + f" amplitude {a.amplitude:.4g} ({100 * a.share:.0f} %)" for a in m.attractors))
    print(f"attractors.csv, summary.json and a figure written to {args.out} "
          f"({summary['time_s']:.1f} s)")


def _add_source(parser):
    """--scene | --file, --set, --amplitude: what :func:`_load_system` reads."""
    src = parser.add_mutually_exclusive_group()
    src.add_argument("--scene", default="kelvin_voigt", help="a preset scene")
    src.add_argument("--file", default=None, help="a scene file (.toml or .json)")
    parser.add_argument("--set", action="append", metavar="name=value")
    parser.add_argument("--amplitude", type=float, default=None, help="F0 [N]")


def build_parser():
    p = argparse.ArgumentParser(prog="absorber-jax",
                                description="Impact and friction vibration absorbers in JAX")
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("reproduce-paper", help="write the paper's figures and our amplitudes")
    r.add_argument("--out", default="paper_figures")
    r.add_argument("--quick", action="store_true", help="short simulations (smoke test)")
    r.set_defaults(func=cmd_reproduce)
    s = sub.add_parser("simulate", help="simulate one scene, write CSV (and a PNG)")
    s.add_argument("--scene", default="kelvin_voigt")
    s.add_argument("--t1", type=float, default=2.0)
    s.add_argument("--solver", default=None)
    s.add_argument("--set", action="append", metavar="field=value")
    s.add_argument("--out", default="trajectory.csv")
    s.add_argument("--plot", default=None)
    s.set_defaults(func=cmd_simulate)
    w = sub.add_parser("sweep", help="steady-state frequency response, CSV and PNG")
    w.add_argument("--scene", default="kelvin_voigt")
    w.add_argument("--omega", default="30:70:64", help="LO:HI:N [rad/s]")
    w.add_argument("--amplitude", type=float, default=None, help="F0 [N] (scene default)")
    w.add_argument("--set", action="append", metavar="field=value")
    w.add_argument("--method", default="shooting", choices=["shooting", "marching"])
    w.add_argument("--direction", default="parallel", choices=["parallel", "up", "down", "both"])
    w.add_argument("--chunk", type=int, default=64)
    w.add_argument("--out", default="frf.csv")
    w.add_argument("--plot", default="frf.png")
    w.set_defaults(func=cmd_sweep)
    t = sub.add_parser("tune", help="tune absorber parameters to minimise the band peak")
    t.add_argument("--scene", default="kelvin_voigt")
    t.add_argument("--params", required=True, help="comma-separated, e.g. k1,c1,m")
    t.add_argument("--band", required=True, help="LO:HI [rad/s]")
    t.add_argument("--amplitude", type=float, default=None)
    t.add_argument("--objective", default="exact_peak",
                   choices=["exact_peak", "robust_peak", "peak", "mean_square"])
    t.add_argument("--steps", type=int, default=40)
    t.add_argument("--n-freq", type=int, default=32)
    t.add_argument("--set", action="append", metavar="field=value")
    t.add_argument("--bounds", action="append", metavar="name=LO:HI")
    t.add_argument("--no-confirm", action="store_true", help="skip the marching check")
    t.add_argument("--out", default="tuning")
    t.set_defaults(func=cmd_tune)
    sc = sub.add_parser("scene", help="a scene file (TOML or JSON: structure, elements, "
                        "load, sweep): sweep, CSV, JSON summary and PNG per degree of freedom")
    sc.add_argument("file", help="scene file (.toml or .json); schema: absorber_jax/_scene.py")
    sc.add_argument("--out", default="scene_out", help="output folder")
    sc.add_argument("--set", action="append", metavar="name=value",
                    help="replace a parameter, e.g. tmd1.k=5e4 or friction1.N=0.05")
    sc.add_argument("--omega", default=None, help="LO:HI:N [rad/s] (default the file's sweep)")
    sc.add_argument("--amplitude", type=float, default=None, help="F0 [N] (default the file's)")
    sc.add_argument("--direction", default=None, choices=["parallel", "up", "down", "both"])
    sc.add_argument("--method", default=None, choices=["shooting", "marching"])
    sc.add_argument("--chunk", type=int, default=64)
    sc.add_argument("--simulate", action="store_true",
                    help="also simulate from rest at the peak (or [simulate] omega)")
    sc.add_argument("--progress", action="store_true", help="show a progress bar")
    sc.set_defaults(func=cmd_scene)
    cn = sub.add_parser("continue", help="continuation of periodic orbits through folds, "
                        "with bifurcations (CSV, JSON, PNG)")
    _add_source(cn)
    cn.add_argument("--parameter", default="omega",
                    help="omega, amplitude or a system parameter (k1, gap, tmd1.k, ...)")
    cn.add_argument("--bounds", required=True, help="LO:HI of the parameter")
    cn.add_argument("--start", type=float, default=None,
                    help="start value (omega: default the bound the direction leaves)")
    cn.add_argument("--omega", type=float, default=None,
                    help="forcing frequency when continuing in another parameter")
    cn.add_argument("--direction", default="up", choices=["up", "down"])
    cn.add_argument("--n", type=int, default=1, help="period multiple")
    cn.add_argument("--step", type=float, default=0.01)
    cn.add_argument("--max-step", type=float, default=0.05)
    cn.add_argument("--max-points", type=int, default=400)
    cn.add_argument("--switch", action="store_true",
                    help="also follow the period-2n branches born at period doublings")
    cn.add_argument("--out", default="continuation")
    cn.add_argument("--progress", action="store_true")
    cn.set_defaults(func=cmd_continue)
    at = sub.add_parser("attractors", help="attractor map at one frequency, or a "
                        "stroboscopic bifurcation diagram over a range (CSV, JSON, PNG)")
    _add_source(at)
    at.add_argument("--omega", required=True, help="W [rad/s], or LO:HI:N for a diagram")
    at.add_argument("--samples", type=int, default=32, help="initial states")
    at.add_argument("--seed", type=int, default=0)
    at.add_argument("--n-max", type=int, default=8)
    at.add_argument("--max-periods", type=int, default=2000)
    at.add_argument("--give-up", type=int, default=None,
                    help="periods after which a lane that is not settling stops "
                         "(default max-periods / 4; = max-periods: march every lane to the end)")
    at.add_argument("--window", type=int, default=40, help="periods of statistics")
    at.add_argument("--out", default="attractors")
    at.add_argument("--progress", action="store_true")
    at.set_defaults(func=cmd_attractors)
    wp = sub.add_parser("work-precision", help="error against run time for every law and solver")
    wp.add_argument("--out", default="work_precision")
    wp.add_argument("--resume", action="store_true",
                    help="reuse the per-scene results already written to --out")
    wp.add_argument("--quick", action="store_true")
    wp.set_defaults(func=cmd_work_precision)
    return p


def main(argv=None):
    args = build_parser().parse_args(argv)
    try:
        args.func(args)
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
