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
    from ._paper import reproduce_paper

    summary = reproduce_paper(args.out, quick=args.quick)
    print(json.dumps(summary["conclusions"], indent=2))
    print(f"figures, summary.json and amplitudes.csv written to {args.out}")


def cmd_simulate(args):
    import csv
    import os

    import numpy as np

    from . import presets
    from ._simulate import simulate

    system, forcing = presets.scene(args.scene)
    sets = _parse_sets(args.set)
    if sets:
        from ._params import with_params

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
