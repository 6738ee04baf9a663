"""Command line: ``absorber-jax`` (or ``python -m absorber_jax``)."""

from __future__ import annotations

import argparse
import json
import sys

from .. import presets
from .._continuation.continuation import continuation
from .._continuation.method import PseudoArclength
from .._core.status import describe, hint
from .._core.status import name as status_name
from .._core.tables import attractor_columns, write_csv
from .._core.units import signals_of, with_unit
from .._design.objectives import BY_NAME
from .._design.tune import plot_tuning, tune
from .._integration.settings import Integrator
from .._integration.simulate import simulate
from .._periodic.attractors import attractors, bifurcation_diagram
from .._periodic.marching import Marching
from .._periodic.sweep import frequency_response
from .._systems.forcing import Harmonic
from .._systems.params import get_param, replace_params, with_params
from .paper import reproduce_paper
from .plots import (
    _sweep_words,
    mark_failed,
    plot_bifurcation_diagram,
    plot_branches,
    plot_frequency_response,
)
from .scene import load_scene


def _parse_sets(items):
    out = {}
    for item in items or []:
        if "=" not in item:
            raise SystemExit(f"--set expects field=value, got {item!r}")
        k, v = item.split("=", 1)
        out[k.strip()] = float(v)
    return out


def cmd_reproduce(args):

    summary = reproduce_paper(args.out, quick=args.quick)
    print(json.dumps(summary["conclusions"], indent=2))
    print(f"figures, summary.json and amplitudes.csv written to {args.out}")


def _sweeps(frequency_response, system, omegas, amplitude, method, direction, chunk,
            progress):
    """The sweeps of a CLI command: one, or up and down for ``direction="both"``; the
    points per compiled call passed on only when asked for."""
    extra = {} if chunk in (None, 64) else {"chunk_size": chunk}
    directions = ("up", "down") if direction == "both" else (direction,)
    return [frequency_response(system, omegas, amplitude=amplitude, method=method,
                               direction=d, progress=progress, **extra) for d in directions]


def _warn(text):
    """A warning line on stderr (the results are still written)."""
    print(f"warning: {text}", file=sys.stderr)


def _failure_lines(frfs):
    """One line per failure code over the sweeps ``frfs``: how many points, at which ω,
    what failed and what to try (``describe``)."""
    import numpy as np


    by_code = {}
    for f in frfs:
        st = np.atleast_2d(np.asarray(f.status))
        om = np.asarray(f.omegas)
        for p, i in np.argwhere(st != 0):
            by_code.setdefault(int(st[p, i]), []).append(float(om[i]))
    lines = []
    for code, oms in sorted(by_code.items()):
        shown = ", ".join(f"{w:.4g}" for w in sorted(set(oms))[:8])
        more = " ..." if len(set(oms)) > 8 else ""
        lines.append(f"{len(oms)} point(s) failed at ω = {shown}{more} rad/s: "
                     f"{describe(code)}")
    return lines


def cmd_simulate(args):
    import os

    import numpy as np


    system, forcing = presets.scene(args.scene)
    sets = _parse_sets(args.set)
    if sets:

        system = with_params(system, sets)
    tr = simulate(system, forcing, args.t1, integrator=Integrator(solver=args.solver),
                  throw=False)
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    tr.to_csv(args.out)
    failed = int(tr.status) != 0
    if failed:
        _warn(f"the integration failed: {describe(tr.status)}")
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        f, ax = plt.subplots(figsize=(8, 4))
        ax.plot(np.asarray(tr.ts), np.asarray(tr.x1) * 1e3, lw=0.7, label="x1 (primary)")
        ax.plot(np.asarray(tr.ts), np.asarray(tr.x2) * 1e3, lw=0.7,
                label="x2 (absorber, absolute)")
        ax.set(xlabel="time t [s]", ylabel="displacement [mm]",
               title=args.scene + (" (integration failed)" if failed else ""))
        ax.legend()
        f.tight_layout()
        f.savefig(args.plot, dpi=110)
    print(f"{args.scene}: {int(tr.num_steps)} steps with {tr.solver}; x1 amplitude "
          f"(last 10 periods) {tr.amplitude() * 1e3:.4f} mm -> {args.out} "
          f"(SI units: m, m/s, N)")
    return 1 if failed else 0


def _steady_scene(args):
    """The scene named by ``--scene`` under a constant harmonic force, with ``--set`` applied."""

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


    lo, hi, n = _parse_range(args.omega, "--omega")
    system, forcing = _steady_scene(args)
    amplitude = args.amplitude if args.amplitude is not None else float(forcing.amplitude)
    om = np.linspace(lo, hi, n)
    t = time.perf_counter()
    frfs = _sweeps(frequency_response, system, om, amplitude, args.method, args.direction,
                   args.chunk, True)
    elapsed = time.perf_counter() - t
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
    lines = _failure_lines(frfs)
    for line in lines:
        _warn(line)
    print(json.dumps({"scene": args.scene, "points": n * len(frfs), "failed": failed,
                      "failures": lines, "seconds": round(elapsed, 3), "csv": args.out,
                      "png": args.plot, "units": "SI (omega rad/s, amplitudes m)"}))


def cmd_tune(args):
    import csv
    import json
    import os

    import numpy as np


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
    for name in bounds:
        if name not in params:
            raise ValueError(f"--bounds given for {name!r}, which is not tuned ({params})")
    tuned, hist = tune(system, {k: bounds.get(k) for k in params}, (lo, hi),
                       amplitude=amplitude, objective=objective, steps=args.steps, progress=True,
                       confirm=not args.no_confirm)
    os.makedirs(args.out, exist_ok=True)
    plot_tuning(system, tuned, hist, os.path.join(args.out, "tuning.png"),
                title=f"{args.scene}: {', '.join(params)} over {lo:g}–{hi:g} rad/s")
    with open(os.path.join(args.out, "curves.csv"), "w", newline="") as fh:
        w = csv.writer(fh)
        obs = signals_of(system)
        w.writerow([with_unit("omega", "rad/s"),
                    with_unit(f"amplitude {obs.observable} before", obs.observable_unit),
                    with_unit(f"amplitude {obs.observable} after", obs.observable_unit)])
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
    """Amplitude of every degree of freedom (absolute displacement, SI units, log scale)
    against frequency: lines broken at failed points, filled markers stable, open markers
    unstable, red crosses on the bottom edge failed points."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np


    fig, ax = plt.subplots(figsize=(8, 4.5))
    colors = plt.get_cmap("tab10")
    styles = {"up": "^", "down": "v"}
    sig = frfs[0].signals
    units = sorted({sig.dof_unit(n) for n in dof_names})
    any_failed = any_unstable = False
    for frf in frfs:
        om = np.asarray(frf.omegas)
        ok = np.asarray(frf.status) == 0
        st = np.asarray(frf.stable).astype(bool)
        mk = styles.get(frf.direction, "o")
        words = _sweep_words(frf.direction)
        tag = f" ({words})" if words and len(frfs) > 1 else ""
        for j, name in enumerate(dof_names):
            a = np.where(ok, np.asarray(frf.dof(name, "amplitude"), dtype=float), np.nan)
            c = colors(j % 10)
            # the line and the stable points in one artist: the legend shows both
            ax.plot(om, np.where(st, a, np.nan), "-", marker=mk, ms=3, lw=0.8, color=c,
                    label=f"{name}{tag}")
            ax.plot(om, a, "-", lw=0.8, color=c)
            if (ok & ~st).any():
                any_unstable = True
                ax.plot(om[ok & ~st], a[ok & ~st], mk, ls="none", ms=5, mfc="none", color=c)
        if (~ok).any():
            any_failed = True
            mark_failed(ax, om[~ok])
    if any_unstable:
        ax.plot([], [], "o", ls="none", ms=5, mfc="none", color="0.3", label="unstable")
    if any_failed:
        mark_failed(ax, [np.nan], label="failed")
    ax.set_yscale("log")
    ax.set(xlabel=with_unit("forcing frequency ω", "rad/s"),
           ylabel=with_unit("amplitude of each degree of freedom (absolute, half "
                            "peak-to-peak)", " or ".join(units)), title=title)
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
    frfs = _sweeps(frequency_response, system, omegas, amplitude, method, direction,
                   args.chunk, args.progress)
    t_swept = time.perf_counter()
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
        codes = np.asarray(f.status)
        failures += [{"direction": f.direction, "omega": float(om[i[-1]]),
                      "status": status_name(codes[tuple(i)]),
                      "meaning": describe(codes[tuple(i)], hint=False),
                      "try": hint(codes[tuple(i)])} for i in np.argwhere(codes != 0)]
    sig = frfs[0].signals
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
        "units": {"omega": "rad/s", "amplitude": "SI (m; rad on a rotational degree of freedom)",
                  "observable": sig.observable, "observable_units": sig.observable_unit,
                  "parameters": {k: sig.parameter_unit(k) for k in params}},
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
            w.writerow([with_unit("t", "s"),
                        *(with_unit(n, sig.dof_unit(n)) for n in system.output_names),
                        *(with_unit(f"force {e}", "N") for e in system.element_names)])
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
        ax.set(xlabel=with_unit("time t", "s"),
               ylabel=with_unit("displacement", " or ".join(sorted(
                   {sig.dof_unit(n) for n in dof_names}))),
               title=f"{title}\nfrom rest at ω = {omega:.4g} rad/s")
        ax.legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(os.path.join(args.out, "trajectory.png"), dpi=110)
        plt.close(fig)
        summary["timing_s"]["simulate"] = round(time.perf_counter() - t, 3)
    summary["timing_s"]["total"] = round(time.perf_counter() - t_start, 3)
    with open(os.path.join(args.out, "summary.json"), "w") as fh:
        json.dump(summary, fh, indent=2)
    pk = (f"peak {best['amplitude']:.4g} {sig.observable_unit} at ω = {best['omega']:.4g} rad/s"
          + ("" if best["stable"] else " (unstable)")) if best else "no successful point"
    for line in _failure_lines(frfs):
        _warn(line)
    print(f"{title}: {summary['points']} points, {len(failures)} failed, {unstable} unstable; "
          f"observable {sig.observable} {pk}; sweep {summary['timing_s']['sweep']:.1f} s "
          f"-> {args.out} (SI units)")
    for nm, v in per_dof.items():
        print(f"  {nm:>12s}: peak {v['amplitude']:.4g} {sig.dof_unit(nm)} at "
              f"ω = {v['omega']:.4g} rad/s")
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
        for (i,), text in br.failures():
            _warn(f"branch point {i} ({args.parameter} = {float(br.values[i]):.6g}) failed: "
                  f"{text}")
    print(f"CSV, summary.json and branches.png written to {args.out} "
          f"({summary['time_s']:.1f} s; SI units)")


def cmd_study(args):
    """A design study described in a scene file's ``[study]``: the store (resumed
    when it exists), summary.json, designs.csv (one row per design, SI units) and
    study.png (the peak over the design space, or its distribution)."""
    import os

    import numpy as np

    from .._study.study import study

    system, settings = load_scene(args.file)
    spec = settings.study
    if spec is None:
        raise ValueError(f"{args.file} has no [study] table (see absorber-jax study --help)")
    os.makedirs(args.out, exist_ok=True)
    store = args.store or spec.store or os.path.join(args.out, "study.zarr")
    client, cluster = None, None
    if args.scheduler or args.workers:
        from distributed import Client, LocalCluster

        if args.scheduler:
            client = Client(args.scheduler)
        else:
            cluster = LocalCluster(n_workers=args.workers, threads_per_worker=1,
                                   processes=True, dashboard_address=None)
            client = Client(cluster)
    try:
        res = study(system, spec.designs, spec.question, store=store,
                    chunk=args.chunk or spec.chunk, client=client,
                    progress=not args.quiet)
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
    d = res.data
    summary = dict(res.summary(), title=settings.title, scene=args.file)
    with open(os.path.join(args.out, "summary.json"), "w") as f:
        json.dump(summary, f, indent=2, default=float)
    per_design = [k for k, v in d.data_vars.items()
                  if set(v.dims) <= set(d.attrs["design_dims"].split(","))]
    if per_design:
        frame = d[per_design].to_dataframe().reset_index()
        frame = frame.rename(columns={c: with_unit(c, d[c].attrs.get("units", ""))
                                      for c in frame.columns if c in d})
        frame.to_csv(os.path.join(args.out, "designs.csv"), index=False)
    if "peak" in d and np.isfinite(np.asarray(d["peak"], dtype=float)).any():
        import matplotlib.pyplot as plt

        plt.close(res.plot(os.path.join(args.out, "study.png")))
    print(f"{summary['designs']} designs: {summary['chunks_computed']} chunks computed, "
          f"{summary['chunks_reused']} read from {store}; {summary['failed_points']} failed "
          f"points; summary.json, designs.csv and study.png written to {args.out}")
    return 0


def _load_system(args):
    """(system, F0, title, sets) from --file (a scene file) or --scene (a preset), with the
    --set replacements and --amplitude applied."""
    import os

    if args.file:

        system, settings = load_scene(args.file)
        amplitude = settings.amplitude
        title = settings.title or os.path.splitext(os.path.basename(args.file))[0]
    else:

        system, forcing = presets.scene(args.scene)
        amplitude, title = float(forcing.amplitude), args.scene
    sets = _parse_sets(args.set)
    if sets:

        system = replace_params(system, sets)
    if args.amplitude is not None:
        amplitude = args.amplitude
    return system, amplitude, title, sets


def cmd_attractors(args):
    """Attractor map at one frequency (--omega W) or a stroboscopic bifurcation diagram
    over a range (--omega LO:HI:N): JSON summary, CSV per initial state, PNG."""
    import json
    import os
    import time

    import numpy as np


    t0 = time.perf_counter()
    system, amplitude, title, sets = _load_system(args)
    opts = dict(samples=args.samples, window=args.window, seed=args.seed,
                method=Marching(n_max=args.n_max, max_periods=args.max_periods, tol=1e-6,
                                give_up=args.give_up))
    os.makedirs(args.out, exist_ok=True)
    if ":" in args.omega:
        lo, hi, n = _parse_range(args.omega, "--omega")
        omegas = np.linspace(lo, hi, n)
        maps = bifurcation_diagram(system, Harmonic(amplitude=amplitude, omega=lo), omegas,
                                   progress=args.progress, **opts)
    else:
        w = float(args.omega)
        maps = [attractors(system, Harmonic(amplitude=amplitude, omega=w), **opts)]
    # one table over all maps: the rows of each map's to_csv, one after the other
    parts = [attractor_columns(m) for m in maps]
    write_csv(os.path.join(args.out, "attractors.csv"),
              [(h, np.concatenate([np.asarray(p[j][1]) for p in parts]))
               for j, (h, _) in enumerate(parts[0])])
    summary = {"scene": args.file or args.scene, "F0": amplitude, "set": sets,
               "samples": args.samples, "window": args.window, "seed": args.seed,
               "n_max": args.n_max, "max_periods": args.max_periods, "give_up": args.give_up,
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
        sig = m.signals
        fig, ax = plt.subplots(figsize=(6, 5))
        names = system.state_names
        u = sig.observable_unit
        for i, a in enumerate(m.attractors):
            sel = m.label == i
            kind = f"period-{a.period_multiple}" if a.periodic else a.kind
            ax.plot(m.initial_states[sel, 0], m.initial_states[sel, 1], "o", ls="none", ms=5,
                    label=f"{kind}: {sig.observable} amplitude {a.amplitude:.4g} {u}, "
                          f"peak {a.peak:.4g} {u}, {a.impacts:.3g} impacts/period "
                          f"({100 * a.share:.0f} %)")
        ax.set(xlabel=with_unit(f"{names[0]}(0)", sig.state_unit(names[0])),
               ylabel=with_unit(f"{names[1]}(0)", sig.state_unit(names[1])),
               title=f"{title}: attractors at ω = {m.omega:g} rad/s")
        ax.legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(os.path.join(args.out, "attractors.png"), dpi=110)
        plt.close(fig)
    for m in maps:
        print(f"ω = {m.omega:g}: " + "; ".join(
            (f"period-{a.period_multiple}" if a.periodic else a.kind)
            + f" {m.signals.observable} amplitude {a.amplitude:.4g} {m.signals.observable_unit}"
            + f" ({100 * a.share:.0f} %)" for a in m.attractors))
    print(f"attractors.csv, summary.json and a figure written to {args.out} "
          f"({summary['time_s']:.1f} s)")


_SCENES = ("kelvin_voigt", "hertz", "hunt_crossley", "coulomb", "stribeck", "dahl", "lugre",
           "stribeck_physical", "lugre_physical")
_SCENE_HELP = ("a preset scene of the paper: impact " + ", ".join(_SCENES[:3]) + "; friction "
               + ", ".join(_SCENES[3:]))
_SET_HELP = ("replace a parameter of the system (SI units), e.g. k1=500, gap=2e-3, N=5 or, in a "
             "scene file, tmd1.k=5e4; repeat for several (default: none)")


class _HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Each option's help followed by its default, except where the default is None (the
    help says what then applies) or the option is a flag."""

    def _get_help_string(self, action):
        if action.default is None or isinstance(action.default, bool):
            return action.help
        return super()._get_help_string(action)


def _command(sub, name, help, description):
    """A subcommand with its one-line ``help`` (in the command list) and ``description``
    (on its own ``--help``), options shown with their defaults."""
    return sub.add_parser(name, help=help, description=description,
                          formatter_class=_HelpFormatter)


def _add_source(parser):
    """--scene | --file, --set, --amplitude: what ``_load_system`` reads."""
    src = parser.add_mutually_exclusive_group()
    src.add_argument("--scene", default="kelvin_voigt", help=_SCENE_HELP)
    src.add_argument("--file", default=None,
                     help="a scene file (.toml or .json: structure, elements, load) instead "
                          "of --scene")
    parser.add_argument("--set", action="append", metavar="name=value", help=_SET_HELP)
    parser.add_argument("--amplitude", type=float, default=None,
                        help="forcing amplitude F0 [N] (default: the scene's)")


def build_parser():
    p = argparse.ArgumentParser(
        prog="absorber-jax", formatter_class=_HelpFormatter,
        description="Impact and friction vibration absorbers in JAX: simulations, "
                    "steady-state frequency responses, continuation, attractor maps and "
                    "tuning.  Files hold SI values (m, rad, s, N, rad/s), each CSV header "
                    "naming its unit; plots show millimetres where labelled so.")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    r = _command(sub, "reproduce-paper", "write the paper's figures and our amplitudes",
                 "Simulate every scene of the paper and write its figures (PNG), "
                 "summary.json and amplitudes.csv (SI units) to --out.")
    r.add_argument("--out", default="paper_figures", help="output folder")
    r.add_argument("--quick", action="store_true",
                   help="short simulations (a smoke test, not the paper's durations)")
    r.set_defaults(func=cmd_reproduce)
    s = _command(sub, "simulate", "simulate one scene, write CSV (and a PNG)",
                 "Integrate a preset scene from rest to --t1 and write the trajectory as CSV "
                 "(t [s], the state x1 [m], v1 [m/s], x2 [m] (absolute), v2 [m/s], law "
                 "states, the coupling force [N] and, for friction scenes, the friction "
                 "force, force ratio and regime); optionally a PNG of x1 and x2 in mm.  A "
                 "failed integration is reported with what to try (exit code 1).")
    s.add_argument("--scene", default="kelvin_voigt", help=_SCENE_HELP)
    s.add_argument("--t1", type=float, default=2.0, help="final time [s]")
    s.add_argument("--solver", default=None,
                   help="integrator: tsit5, dopri5, dopri8, bosh3, kvaerno3, kvaerno5 or auto "
                        "(default: auto, implicit kvaerno5 for a stiff scene)")
    s.add_argument("--set", action="append", metavar="name=value", help=_SET_HELP)
    s.add_argument("--out", default="trajectory.csv", help="CSV file written (SI units)")
    s.add_argument("--plot", default=None,
                   help="PNG file of x1 and x2 against time, in mm (default: no plot)")
    s.set_defaults(func=cmd_simulate)
    w = _command(sub, "sweep", "steady-state frequency response, CSV and PNG",
                 "Periodic steady states of a preset scene over a grid of forcing "
                 "frequencies: a CSV with one row per frequency (omega [rad/s], the "
                 "observable's amplitude [m], the absorber stroke x2 - x1 (relative motion) "
                 "[m], each degree of freedom's absolute amplitude [m], stability, status "
                 "and its text; nan at failed points) and a PNG in mm.  Failed points are "
                 "listed on stderr with what to try.")
    w.add_argument("--scene", default="kelvin_voigt", help=_SCENE_HELP)
    w.add_argument("--omega", default="30:70:64",
                   help="frequency grid LO:HI:N: N frequencies from LO to HI [rad/s]")
    w.add_argument("--amplitude", type=float, default=None,
                   help="forcing amplitude F0 [N] (default: the scene's)")
    w.add_argument("--set", action="append", metavar="name=value", help=_SET_HELP)
    w.add_argument("--method", default="shooting", choices=["shooting", "marching"],
                   help="steady-state solver: shooting (Newton on the period map, from the "
                        "linear guess; Floquet stability) or marching (integrate until the "
                        "response repeats: the attractor reached from rest)")
    w.add_argument("--direction", default="parallel", choices=["parallel", "up", "down", "both"],
                   help="parallel: every frequency solved on its own; up / down: each "
                        "frequency started from its neighbour's orbit as ω increases / "
                        "decreases (follows a branch, shows hysteresis); both: up and down, "
                        "written to <out>_up.csv and <out>_down.csv")
    w.add_argument("--chunk", type=int, default=64,
                   help="frequencies per compiled call (memory against compilation reuse)")
    w.add_argument("--out", default="frf.csv", help="CSV file written (SI units)")
    w.add_argument("--plot", default="frf.png",
                   help="PNG file of the observable's amplitude in mm (empty: no plot)")
    w.set_defaults(func=cmd_sweep)
    t = _command(sub, "tune", "tune absorber parameters to minimise the band peak",
                 "Optimise absorber parameters (--params) so that the observable's amplitude "
                 "over a frequency band is smallest (--objective); writes tuning.png, "
                 "curves.csv (amplitude before and after [m]) and tuning.json to --out.")
    t.add_argument("--scene", default="kelvin_voigt", help=_SCENE_HELP)
    t.add_argument("--params", required=True,
                   help="parameters tuned, comma-separated, e.g. k1,c1,m (required)")
    t.add_argument("--band", required=True,
                   help="frequency band LO:HI [rad/s] (required)")
    t.add_argument("--amplitude", type=float, default=None,
                   help="forcing amplitude F0 [N] (default: the scene's)")
    t.add_argument("--objective", default="exact_peak",
                   choices=["exact_peak", "robust_peak", "peak", "mean_square"],
                   help="exact_peak: the band's largest amplitude, located exactly; "
                        "robust_peak: also the coexisting stable responses; peak: a smooth "
                        "maximum over the grid; mean_square: mean squared amplitude [m^2]")
    t.add_argument("--steps", type=int, default=40,
                   help="optimiser steps (SLSQP iterations for the peak objectives)")
    t.add_argument("--n-freq", type=int, default=32,
                   help="frequencies of the grid over the band")
    t.add_argument("--set", action="append", metavar="name=value", help=_SET_HELP)
    t.add_argument("--bounds", action="append", metavar="name=LO:HI",
                   help="bounds of a tuned parameter in its SI unit, e.g. k1=100:2000; "
                        "repeat for several (default: positive, unbounded)")
    t.add_argument("--no-confirm", action="store_true",
                   help="skip the check of the curves before and after by marching")
    t.add_argument("--out", default="tuning", help="output folder")
    t.set_defaults(func=cmd_tune)
    sc = _command(sub, "scene", "a scene file: sweep, CSV, JSON summary and PNG per degree "
                  "of freedom",
                  "Load a scene file (TOML or JSON: structure, elements, load, sweep; keys "
                  "and units on the 'Scene files and the CLI' page of the documentation), "
                  "sweep it, and write "
                  "frequency_response.csv (SI units, nan at failed points), a PNG of every "
                  "degree of freedom's amplitude and summary.json (peaks, failures with what "
                  "to try); --simulate adds trajectory.csv and trajectory.png.")
    sc.add_argument("file", help="scene file (.toml or .json)")
    sc.add_argument("--out", default="scene_out", help="output folder")
    sc.add_argument("--set", action="append", metavar="name=value", help=_SET_HELP)
    sc.add_argument("--omega", default=None,
                    help="frequency grid LO:HI:N [rad/s] (default: the file's [sweep])")
    sc.add_argument("--amplitude", type=float, default=None,
                    help="forcing amplitude F0 [N] (default: the file's)")
    sc.add_argument("--direction", default=None, choices=["parallel", "up", "down", "both"],
                    help="as for sweep (default: the file's, else parallel)")
    sc.add_argument("--method", default=None, choices=["shooting", "marching"],
                    help="as for sweep (default: the file's, else shooting)")
    sc.add_argument("--chunk", type=int, default=64,
                    help="frequencies per compiled call")
    sc.add_argument("--simulate", action="store_true",
                    help="also simulate from rest at the observable's peak (or the file's "
                         "[simulate] omega)")
    sc.add_argument("--progress", action="store_true", help="show a progress bar")
    sc.set_defaults(func=cmd_scene)
    cn = _command(sub, "continue", "continuation of periodic orbits through folds, with "
                  "bifurcations (CSV, JSON, PNG)",
                  "Follow a branch of periodic orbits in a parameter (pseudo-arclength "
                  "continuation, through folds), locate its folds, period doublings and "
                  "Neimark-Sacker bifurcations, and write branch.csv (SI units), "
                  "summary.json and branches.png to --out.")
    _add_source(cn)
    cn.add_argument("--parameter", default="omega",
                    help="the parameter continued in: omega [rad/s], amplitude [N] or a "
                         "system parameter (k1, gap, tmd1.k, ...) in its SI unit")
    cn.add_argument("--bounds", required=True,
                    help="LO:HI of the parameter, in its unit (required)")
    cn.add_argument("--start", type=float, default=None,
                    help="start value of the parameter (default: for omega, the bound the "
                         "direction leaves; else the system's own value)")
    cn.add_argument("--omega", type=float, default=None,
                    help="forcing frequency [rad/s] when continuing in another parameter "
                         "(required then)")
    cn.add_argument("--direction", default="up", choices=["up", "down"],
                    help="the way the parameter moves first")
    cn.add_argument("--n", type=int, default=1,
                    help="period multiple of the orbits (in forcing periods)")
    cn.add_argument("--step", type=float, default=0.01,
                    help="first arclength step, dimensionless (the parameter over its "
                         "start value, the orbit state over its scale)")
    cn.add_argument("--max-step", type=float, default=0.05,
                    help="largest arclength step, dimensionless (the parameter over its "
                         "start value, the orbit state over its scale)")
    cn.add_argument("--max-points", type=int, default=400, help="most points per branch")
    cn.add_argument("--switch", action="store_true",
                    help="also follow the period-2n branches born at period doublings")
    cn.add_argument("--out", default="continuation", help="output folder")
    cn.add_argument("--progress", action="store_true", help="show a progress bar")
    cn.set_defaults(func=cmd_continue)
    at = _command(sub, "attractors", "attractor map at one frequency, or a stroboscopic "
                  "bifurcation diagram over a range (CSV, JSON, PNG)",
                  "March many initial states at one forcing (--omega W) and group the "
                  "responses they settle on (periodic, quasi-periodic, chaotic) with their "
                  "statistics, or do so over a frequency range (--omega LO:HI:N) for a "
                  "stroboscopic bifurcation diagram; writes attractors.csv (SI units), "
                  "summary.json and a PNG to --out.")
    _add_source(at)
    at.add_argument("--omega", required=True,
                    help="forcing frequency W [rad/s], or LO:HI:N for a diagram (required)")
    at.add_argument("--samples", type=int, default=32,
                    help="initial states, uniform in a box around rest")
    at.add_argument("--seed", type=int, default=0, help="random seed of the initial states")
    at.add_argument("--n-max", type=int, default=8,
                    help="largest period multiple recognised (in forcing periods)")
    at.add_argument("--max-periods", type=int, default=2000,
                    help="marching budget per initial state, in forcing periods")
    at.add_argument("--give-up", type=int, default=None,
                    help="forcing periods after which a lane that is not settling stops "
                         "(default: max-periods / 4; = max-periods: march every lane to the "
                         "end)")
    at.add_argument("--window", type=int, default=40,
                    help="forcing periods of the statistics window after marching")
    at.add_argument("--out", default="attractors", help="output folder")
    at.add_argument("--progress", action="store_true", help="show a progress bar")
    at.set_defaults(func=cmd_attractors)
    sd = _command(sub, "study", "a design study from a scene file: a resumable store, "
                  "CSV, JSON and a PNG",
                  "Ask the question of a scene file's [study] table (frequency_response, "
                  "exact_peak or robust_peak) of every design of its design set (grid, "
                  "designs, monte_carlo or latin_hypercube), chunk by chunk into a store "
                  "(Zarr format) "
                  "(run again to resume: only missing chunks are computed; a store made for "
                  "another study is refused), locally or on Dask workers.  Writes "
                  "summary.json, designs.csv (one row per design, SI units) and study.png "
                  "(the peak over the design space, or its distribution) to --out.")
    sd.add_argument("--file", required=True, help="the scene file (.toml or .json) with a "
                    "[study] table (required)")
    sd.add_argument("--store", default=None,
                    help="the store, a directory (default: the scene's study.store, else "
                         "<out>/study.zarr)")
    sd.add_argument("--chunk", type=int, default=None,
                    help="designs per chunk (default: the scene's, else about 256 solves)")
    sd.add_argument("--workers", type=int, default=0,
                    help="run on a local Dask cluster of this many worker processes "
                         "(0: in this process)")
    sd.add_argument("--scheduler", default=None,
                    help="address of a running Dask scheduler (tcp://host:8786) to run on "
                         "instead")
    sd.add_argument("--out", default="study", help="output folder")
    sd.add_argument("--quiet", action="store_true", help="no progress bar")
    sd.set_defaults(func=cmd_study)
    wp = _command(sub, "work-precision", "error against run time for every law and solver",
                  "Run scripts/work_precision.py (needs the repository checkout): the error "
                  "of every contact and friction law under every solver against run time.")
    wp.add_argument("--out", default="work_precision", help="output folder")
    wp.add_argument("--resume", action="store_true",
                    help="reuse the per-scene results already written to --out")
    wp.add_argument("--quick", action="store_true",
                    help="fewer tolerances, scenes and a shorter time budget (a smoke test)")
    wp.set_defaults(func=cmd_work_precision)
    return p


def main(argv=None):
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
