"""Benchmark: rigid impacts (``Restitution``, event-driven) against the penalty route
(a stiff compliant contact), side by side in one run.

Scenes:

- **building**: a 3-storey shear building (1000 kg floors, 1e6 N/m storeys, 2 % modal
  damping), a 50 kg steel ball in a ±10 mm clearance on the top floor, 500 N on the top
  floor, 24 frequencies over the first resonance (12.5–15.5 rad/s).  Penalty: Hertz
  5.2e10 N/m^1.5 (``hertz_stiffness`` of steel on steel, R ≈ 3 cm) with damping 2e4 N s/m;
  rigid: ``e`` from ``restitution_of`` that law at 0.3 m/s.  ``frequency_response`` at its
  defaults, timed with compilation (and again compiled, rigid only); failures counted
  with their messages.
- **hard**: ``ImpactAbsorber(M=1, k=1e3, c=0.5, m=0.2, gap=2e-3)``, F0 = 3 N, band 20–45
  rad/s, continued in ω from 20 up (``continuation`` at its defaults).  Rigid: ``e``
  matched to the Kelvin–Voigt 2e4 N/m, damping 2 N s/m adhesive contact
  (``restitution_of``); penalty: that Kelvin–Voigt law.
- **band**: the hard scene's band 20–45 rad/s by ``band_continuation`` at its defaults,
  both routes, each run twice (the second compiled).
- **band60**: the same band at the settings of ``scripts/benchmark_hard_contacts.py``'s
  (8 starts, at most 60 points a half-branch, rtol = atol = 1e-7, 2 fill passes).

    python scripts/benchmark_rigid_impacts.py [--parts building,hard,band,band60] [--devices N]
                                              [--draws N] [--out FILE]

``--draws N``: the band parts also run N more times compiled, their lower bound moved by
up to 0.03 rad/s (``DRAWS``): the spread of their time and coverage (each draw run twice,
the second timed).

``--devices N``: both routes on N CPU devices (``aj.use_cpu_cores(N)``; default one): the
batched correctors of ``band_continuation`` split their lanes over them.

Prints each result as it comes; ``--out`` appends them to FILE
(docs/benchmark_rigid_impacts.txt holds the last run).
"""

from __future__ import annotations

import argparse
import re
import time
import warnings

import numpy as np

import absorber_jax as aj

LINES = []


def report(line):
    print(line, flush=True)
    LINES.append(line)


def building(contact):
    st = aj.shear_building([1000.0] * 3, [1e6] * 3, modal_damping=0.02)
    ball = aj.ImpactDamper("floor3", m=50.0, gap=0.01, contact=contact)
    return aj.StructuralSystem(st, [ball], load="floor3")


def timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def sweep_building():
    omegas = np.linspace(12.5, 15.5, 24)
    rows = {}
    hertz = aj.Hertz(stiffness=5.2e10, damping=2e4)
    e = aj.restitution_of(hertz, 50.0, 1000.0, 0.3)
    report(f"[building] Hertz 5.2e10 N/m^1.5, 2e4 N s/m gives e = {e:.4f} at 0.3 m/s "
           f"(50 kg on 1000 kg)")
    for name, contact in ((f"rigid e={e:.4f}", aj.Restitution(e)),
                          ("penalty Hertz 5.2e10", hertz)):
        system = building(contact)

        def run(system=system):
            return aj.frequency_response(system, omegas, amplitude=500.0)

        fr, t_first = timed(run)
        # the penalty route is timed once (minutes); the rigid one again, compiled
        fr, t_again = timed(run) if contact.exact else (fr, float("nan"))
        failed = int(np.sum(np.asarray(fr.status) != 0))
        rows[name] = fr
        report(f"[building] {name}: 24 frequencies {t_first:.1f} s with compilation, "
               f"{t_again:.1f} s compiled; failed {failed}; top-floor amplitude "
               f"{np.nanmin(fr.amplitude) * 1e3:.2f}-{np.nanmax(fr.amplitude) * 1e3:.2f} mm; "
               f"impacts/period {np.nanmin(fr.impacts):.0f}-{np.nanmax(fr.impacts):.0f}; "
               f"stable {int(np.sum(fr.stable))}")
        for idx, why in fr.failures():
            report(f"    point {idx}: {why}")
    a, b = (np.asarray(r.amplitude) for r in rows.values())
    both = np.isfinite(a) & np.isfinite(b)
    report(f"[building] rigid vs penalty top-floor amplitude: largest relative difference "
           f"{np.max(np.abs(a[both] - b[both]) / b[both]):.2e} on {int(both.sum())} points")


def continue_hard():
    kv = aj.KelvinVoigt(stiffness=2e4, damping=2.0, adhesive=True)
    e = aj.restitution_of(kv, 0.2, 1.0)
    report(f"[hard] Kelvin-Voigt 2e4 N/m, 2 N s/m (adhesive) gives e = {e:.6f}")
    for name, contact in ((f"rigid e={e:.4f}", aj.Restitution(e)), ("penalty KV 2e4", kv)):
        system = aj.ImpactAbsorber(M=1.0, k=1e3, c=0.5, m=0.2, gap=2e-3, contact=contact)
        forcing = aj.Harmonic(amplitude=3.0, omega=20.0)

        def run(system=system, forcing=forcing):
            return aj.continuation(system, forcing, "omega", bounds=(20.0, 45.0))

        br, t_first = timed(run)
        br, t_again = timed(run)
        v = br.values
        kinds = {k: len(br.of_kind(k))
                 for k in ("fold", "period_doubling", "neimark_sacker", "grazing")}
        report(f"[hard] {name}: continuation from 20 up: {t_first:.1f} s with compilation, "
               f"{t_again:.1f} s compiled; {len(v)} points covering {v.min():.3f}-{v.max():.3f}"
               f" rad/s, ended {br.termination}; bifurcations {kinds}"
               + "".join(f"; grazing at {b.value:.7g} rad/s" for b in br.of_kind("grazing")))


# lower bounds of the band's draws (``--draws``): the same band, its start values moved
DRAWS = (19.99, 20.01, 19.98, 20.02, 19.97, 20.03)


def band_hard(label="band", draws=0, **options):
    """``band_continuation`` over 20-45 rad/s on the hard scene, both routes, each timed twice
    (the second run compiled): points, grazings located, and the parts no branch reached.
    ``options`` go to ``band_continuation`` (both routes).

    ``draws``: also that many compiled runs with the lower bound moved to ``DRAWS`` (the
    starts move with it; each run once untimed first).  In the band's chaotic window
    (28.4-29.8 rad/s) which orbits the starts' Newton solves and marches land on depends
    on the rounding of every earlier step, so the branches found there, and their cost,
    differ from one draw to the next: one run is one sample of that spread."""
    kv = aj.KelvinVoigt(stiffness=2e4, damping=2.0, adhesive=True)
    e = aj.restitution_of(kv, 0.2, 1.0)
    for name, contact in ((f"rigid e={e:.4f}", aj.Restitution(e)), ("penalty KV 2e4", kv)):
        system = aj.ImpactAbsorber(M=1.0, k=1e3, c=0.5, m=0.2, gap=2e-3, contact=contact)
        forcing = aj.Harmonic(amplitude=3.0, omega=20.0)

        def run(system=system, forcing=forcing):
            return band_run(system, forcing, 20.0, options)

        (brs, gaps), t_first = timed(run)
        (brs, gaps), t_again = timed(run)
        points = sum(len(b.values) for b in brs)
        grazings = sum(len(b.of_kind("grazing")) for b in brs)
        ends = {}
        for b in brs:
            ends[b.termination] = ends.get(b.termination, 0) + 1
        report(f"[{label}] {name}: band_continuation 20-45 rad/s: {t_first:.1f} s with "
               f"compilation, {t_again:.1f} s compiled; {len(brs)} half-branches, {points} "
               f"points, {grazings} grazings; ended {ends}"
               + (f"; {gaps[0]}" if gaps else "; the whole band reached"))
        times = [t_again]
        for lo in DRAWS[:draws]:
            # each draw run twice, the second timed: a draw can take a path the others did
            # not (a grazing between impacting orbits) and compile its program first
            def draw(lo=lo, s=system, f=forcing):
                return band_run(s, f, lo, options)

            draw()
            (brs, gaps), t = timed(draw)
            times.append(t)
            report(f"[{label}] {name}: draw from {lo} rad/s: {t:.1f} s compiled, "
                   f"{sum(len(b.values) for b in brs)} points, unreached "
                   f"{unreached(gaps):.3f} rad/s")
        if draws:
            report(f"[{label}] {name}: compiled over {len(times)} draws: median "
                   f"{np.median(times):.1f} s, range {min(times):.1f}-{max(times):.1f} s")


def band_run(system, forcing, lo, options):
    """The hard band from ``lo`` to 45 rad/s: the branches and the warning about the parts
    none reached (if any)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        brs = aj.band_continuation(system, forcing, "omega", bounds=(lo, 45.0), **options)
    return brs, [str(w.message) for w in caught if "no branch reached" in str(w.message)]


def unreached(gaps):
    """The total width [rad/s] of the parts a band warning names."""
    if not gaps:
        return 0.0
    parts = gaps[0].split(" in ", 1)[1].split(";", 1)[0]
    return sum(float(b) - float(a) for a, b in re.findall(r"([0-9.]+)-([0-9.]+)", parts))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--parts", default="building,hard,band")
    ap.add_argument("--out", default=None)
    ap.add_argument("--devices", type=int, default=1)
    ap.add_argument("--draws", type=int, default=0)
    a = ap.parse_args()
    if a.devices > 1:
        aj.use_cpu_cores(a.devices)
        report(f"[setup] {a.devices} CPU devices")
    if "building" in a.parts:
        sweep_building()
    if "hard" in a.parts:
        continue_hard()
    if "band" in a.parts.split(","):
        band_hard(draws=a.draws)
    if "band60" in a.parts.split(","):
        # the settings of scripts/benchmark_hard_contacts.py's band (8 starts, 60 points a
        # half-branch, rtol = atol = 1e-7, 2 fill passes)
        band_hard("band60", draws=a.draws, starts=8, method=aj.PseudoArclength(max_points=60),
                  integrator=aj.Integrator(rtol=1e-7, atol=1e-7))
    if a.out:
        with open(a.out, "a") as fh:
            fh.write("\n".join(LINES) + "\n")


if __name__ == "__main__":
    main()
