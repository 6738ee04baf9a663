"""Benchmark: harmonic balance on finite-element-size structures, time per frequency against
the number of degrees of freedom, and against shooting at equal accuracy.

Scene: the steel cantilever of NLvib example 08 (2 m, 0.1 m high in bending, 0.3 m thick,
E = 185 GPa, ρ = 7830 kg/m³, stiffness-proportional damping β = 8.03e-5 s) meshed with
``n`` Hermite elements (2n degrees of freedom: 100, 1,000, 10,000), a tanh dry-friction
contact (1.5 N, eps = 1e-5 m/s) at 40 % of its length, ``--force`` at the tip (0.2 N);
128 frequencies over 110–370 rad/s (around the first mode, 123 rad/s sliding and 249 rad/s held).

- **Reduction**: ``craig_bampton`` onto the contact's and the tip's deflections plus
  ``--modes`` fixed-interface modes (sparse factorisation and shift-invert Lanczos); its
  time is printed apart.
- **Scale**: ``frequency_response`` with ``HarmonicBalance(harmonics=H)`` (condensed onto the
  contact's degree of freedom), vmapped over the 128 frequencies, compiled (the second of two
  identical calls), per size.  On the 100-DOF mesh also on the unreduced model (the exact
  condensation of all 100 degrees of freedom) for the reduction's error.
- **Equal accuracy** (the 100-DOF mesh's reduced model): the tip's RMS over the band against
  a tight reference (``HarmonicBalance(harmonics=60)``), for harmonic balance at H = 3 … 20
  and for shooting (its default method, vmapped, on the same reduced model) at rtol = atol
  1e-6, 1e-8; each shooting run is set beside the cheapest balance at least as accurate.

    python scripts/benchmark_harmonic_balance.py [--modes 10] [--sizes 50 500 5000]
                                                 [--force 0.2] [--out FILE]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import absorber_jax as aj

LENGTH, E, RHO, HEIGHT, THICK = 2.0, 185e9, 7830.0, 0.1, 0.3
BETA, MU_N, EPS = 8.032992955399717e-05, 1.5, 1e-5
OMEGAS = np.linspace(110.0, 370.0, 128)


def model(n_elements, modes):
    """(system on the Craig–Bampton model, system on the full model or None, reduction
    time [s])."""
    EI, rho_A = E * THICK * HEIGHT**3 / 12, RHO * HEIGHT * THICK
    M, K, names = aj.beam_matrices(n_elements, length=LENGTH, EI=EI, rho_A=rho_A)
    contact, tip = f"w{int(round(0.4 * n_elements))}", f"w{n_elements}"
    damper = aj.FrictionContact(contact, normal_force=MU_N, friction=aj.Coulomb(mu=1.0, eps=EPS))
    t = time.perf_counter()
    cb = aj.craig_bampton(M, K, [contact, tip], modes, rayleigh=(0.0, BETA), dof_names=names)
    t_cb = time.perf_counter() - t
    reduced = aj.StructuralSystem(cb, [damper], load=tip, observe=tip)
    full = None
    if 2 * n_elements <= 200:
        st = aj.structure_from_matrices(M, K, rayleigh=(0.0, BETA), dof_names=names)
        full = aj.StructuralSystem(st, [damper], load=tip, observe=tip)
    return reduced, full, t_cb


def timed(system, method, integrator=None, force=0.2):
    """(rms over the band, statuses, first-call time, compiled time)."""
    def run():
        fr = aj.frequency_response(system, OMEGAS, amplitude=force, floquet=False,
                                   method=method, integrator=integrator)
        return np.asarray(fr.rms), np.asarray(fr.status)

    t = time.perf_counter()
    run()
    first = time.perf_counter() - t
    t = time.perf_counter()
    rms, status = run()
    return rms, status, first, time.perf_counter() - t


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--modes", type=int, default=10)
    ap.add_argument("--sizes", type=int, nargs="+", default=[50, 500, 5000])
    ap.add_argument("--harmonics", type=int, default=7)
    ap.add_argument("--force", type=float, default=0.2,
                    help="tip force amplitude [N] (0.2: the contact mostly sticks; 2: it "
                         "slides over much of the band)")
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    lines = []

    def say(s=""):
        print(s, flush=True)
        lines.append(s)

    say(f"beam with a tanh friction contact, tip force {args.force:g} N, 128 frequencies, "
        f"Craig–Bampton with {args.modes} modes")
    say(f"\n## scale: harmonic balance, H = {args.harmonics}, compiled")
    say(f"{'DOFs':>6} {'reduction [s]':>14} {'band [s]':>9} {'per point [ms]':>15} "
        f"{'first call [s]':>15} {'failed':>6}")
    hb = aj.HarmonicBalance(harmonics=args.harmonics, tol=1e-10)
    small = None
    for n in args.sizes:
        reduced, full, t_cb = model(n, args.modes)
        rms, status, first, t = timed(reduced, hb, force=args.force)
        say(f"{2 * n:6d} {t_cb:14.3f} {t:9.3f} {1e3 * t / len(OMEGAS):15.2f} {first:15.1f} "
            f"{int(np.sum(status != 0)):6d}")
        if full is not None:
            rms_f, status_f, first_f, t_f = timed(full, hb, force=args.force)
            err = np.max(np.abs(rms / rms_f - 1))
            say(f"{'':6} unreduced ({2 * n} coordinates condensed): band {t_f:.3f} s "
                f"({1e3 * t_f / len(OMEGAS):.2f} ms a point); Craig–Bampton's largest "
                f"relative difference of the tip RMS {err:.2e}")
            small = small or reduced

    if small is None:
        return
    say("\n## equal accuracy on the reduced 100-DOF model (tip RMS, largest relative error "
        "over the band)")
    ref, st_ref, _, _ = timed(small, aj.HarmonicBalance(harmonics=60, tol=1e-11),
                            force=args.force)
    assert np.all(st_ref == 0), "reference failed"
    say(f"{'method':>26} {'error':>9} {'band [s]':>9} {'first call [s]':>15} {'failed':>6}")
    balance = []
    for H in (3, 5, 7, 10, 15, 20):
        rms, status, first, t = timed(small, aj.HarmonicBalance(harmonics=H, tol=1e-11),
                                            force=args.force)
        err = float(np.max(np.abs(rms / ref - 1)))
        balance.append((H, err, t))
        say(f"{f'HarmonicBalance(H={H})':>26} {err:9.2e} {t:9.3f} {first:15.1f} "
            f"{int(np.sum(status != 0)):6d}")
    for rtol in (1e-6, 1e-8):
        rms, status, first, t = timed(small, aj.Shooting(),
                                      aj.Integrator(rtol=rtol, atol=rtol), force=args.force)
        ok = status == 0
        err = float(np.max(np.abs(rms[ok] / ref[ok] - 1))) if ok.any() else np.inf
        say(f"{f'Shooting(rtol={rtol:g})':>26} {err:9.2e} {t:9.3f} {first:15.1f} "
            f"{int(np.sum(~ok)):6d}")
        match = [b for b in balance if b[1] <= err]
        if match:
            H, e, th = min(match, key=lambda b: b[2])
            say(f"{'':26} at equal accuracy: HarmonicBalance(H={H}) ({e:.1e}) is "
                f"{t / th:.0f}x faster")
    if args.out:
        with open(args.out, "a") as fh:
            fh.write("\n".join(lines) + "\n\n")


if __name__ == "__main__":
    main()
