"""Benchmark: the exact band peak and its tuning on a linear structure, from the closed-form
response (``StructuralSystem.linear``) against the same computations by shooting, side by
side in one process.

Scene: a 3-storey shear building (2, 2, 1.5 t floors; 4, 3.5, 3 MN/m storeys; Rayleigh
damping 0.2 1/s, 5e-4 s) with a roof tuned mass damper (154 kg, 59.4 kN/m, 770 N s/m),
1 kN on the roof, band 12–32 rad/s (the design-studies notebook's scene).

- ``exact_peak`` with the gradient in the damper's ``k`` and ``c``: timed with compilation
  and again compiled, closed form and shooting; the largest relative differences of the
  peak, its frequency and its gradient;
- ``tune`` of ``k`` and ``c`` at its defaults (the exact peak, SLSQP), from 10 % detuned
  with half the damping: time with compilation, evaluations, the tuned peak.

The shooting route is the same system under a subclass that declares itself not linear
(its own compiled programs).

    python scripts/benchmark_linear_peak.py [--out FILE]
"""

from __future__ import annotations

import argparse
import time

import absorber_jax as aj

LINES = []


def report(line):
    print(line, flush=True)
    LINES.append(line)


class Integrated(aj.StructuralSystem):
    """The same structure, its periodic responses found by shooting."""

    @property
    def linear(self) -> bool:
        return False


def building(cls, k=59405.61008892174, c=770.4357780102641):
    st = aj.shear_building([2.0e3, 2.0e3, 1.5e3], [4.0e6, 3.5e6, 3.0e6], rayleigh=(0.2, 5e-4))
    roof = aj.TunedMassDamper("floor3", m=154.2240340122254, k=k, c=c, name="roof")
    return cls(st, [roof], load="floor3")


def timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default=None)
    a = ap.parse_args()
    band, F0, names = (12.0, 32.0), 1000.0, ("roof.k", "roof.c")
    peaks, times = {}, {}
    for label, cls in (("closed form", aj.StructuralSystem), ("shooting", Integrated)):
        system = building(cls)

        def run(system=system):
            return aj.exact_peak(system, band, amplitude=F0, params=names)

        pk, t_first = timed(run)
        pk, t_again = timed(run)
        peaks[label], times[label] = pk, t_again
        report(f"[exact_peak] {label}: {t_first:.2f} s with compilation, {t_again:.3f} s "
               f"compiled; peak {pk.value * 1e3:.9f} mm at {pk.omega:.9f} rad/s")
    a_, b_ = peaks["closed form"], peaks["shooting"]
    rel = lambda x, y: abs(x - y) / abs(y)  # noqa: E731
    report(f"[exact_peak] closed form / shooting: compiled {times['closed form']:.3f} s vs "
           f"{times['shooting']:.3f} s ({times['shooting'] / times['closed form']:.1f}x); "
           f"peak differs by {rel(a_.value, b_.value):.1e}, frequency by "
           f"{rel(a_.omega, b_.omega):.1e}, gradient by "
           f"{max(rel(a_.gradient[n], b_.gradient[n]) for n in names):.1e} (relative)")
    for label, cls in (("closed form", aj.StructuralSystem), ("shooting", Integrated)):
        system = building(cls, k=1.1 * 59405.61008892174, c=0.5 * 770.4357780102641)
        (tuned, hist), t = timed(lambda system=system: aj.tune(
            system, list(names), band, amplitude=F0, confirm=False))
        report(f"[tune] {label}: {t:.1f} s with compilation, {len(hist['objective'])} "
               f"evaluations; tuned peak {min(hist['objective']) * 1e3:.9f} mm, k "
               f"{float(aj.get_param(tuned, 'roof.k')):.6g} N/m, c "
               f"{float(aj.get_param(tuned, 'roof.c')):.6g} N s/m")
    if a.out:
        with open(a.out, "a") as fh:
            fh.write("\n".join(LINES) + "\n")


if __name__ == "__main__":
    main()
