"""Benchmark: `continuation` against AUTO-07p on NLvib example 03, side by side, at equal
accuracy.

AUTO-07p (Doedel et al.; orthogonal collocation of periodic orbits, pseudo-arclength
continuation, Floquet multipliers from the collocation matrix) is driven through bifpy
(PyPI ``bifpy``, measured at 0.3.0, AUTO-07p compiled with gfortran), which is not a
dependency of absorber_jax:

    apt-get install gfortran        # or your system's Fortran compiler
    pip install bifpy

Without it the script says so and exits 0.  bifpy traces the vector field symbolically and
compiles it into a native AUTO-07p executable (``transpile=True``), so AUTO runs at Fortran
speed; the time printed is the whole ``auto.run`` call, tracing and compilation included
(measured separately as ``--overhead``, a run of two steps: about 0.15 s).

The scene: NLvib's example 03, two unit masses, K = [[1, -1], [-1, 2]], D = 0.03 K, a
unilateral spring of stiffness 100 on q1 beyond 1, 0.1 sin(Ωt) on q2, its period-1 branch
continued from Ω = 0.8 down to 0.5.  Both tools see the same smooth vector field: the spring
force 100 ε softplus((q1 - 1)/ε), absorber_jax's ``KelvinVoigt(100, damping=0, eps=ε,
adhesive=True)``.  For AUTO the forcing is made autonomous with the usual stable oscillator
(s' = s + Ω c - s (s² + c²), c' = -Ω s + c - c (s² + c²), whose limit cycle is
s = sin Ωt, c = cos Ωt), its period a free parameter; the branch starts from the linear
response at Ω = 0.8 (q1 stays below 0.2 there).  AUTO's settings: NCOL = 4, adaptive mesh
(IAD = 3), folds and Floquet bifurcations detected (ILP = 1, ISP = 2), EPSL = EPSU = 1e-7,
EPSS = 1e-5, DS = -0.002, DSMAX = 0.01; with ε = 1e-3 its Jacobian is the exact one from
bifpy's symbolic derivative (the force written log(1 + exp z), which does not overflow at
this ε), with ε = 1e-6 finite differences (the overflow-free form uses max and abs).

Each run reports the six bifurcations of the branch (two folds, two period doublings, two
Neimark–Sacker points) and their worst relative distance from a reference:

- ε = 1e-3: the folds and period doublings from AUTO itself at ``--ntst-ref`` mesh
  intervals (default 400; the change from 300 is printed as the reference's own
  uncertainty); the Neimark–Sacker points from an independent shooting in scipy (DOP853 at
  rtol 1e-12 with the variational equations: Newton on the period map from the orbit
  absorber_jax found there, which only picks which of the coexisting orbits is meant, then
  the secant on the modulus of the complex pair nearest the circle minus 1): AUTO's upper
  torus point stays 1.5e-6 away from where the multipliers cross the circle at every mesh.
- ε = 1e-6: the exact piecewise-linear continuation of the unsmoothed spring
  (``tests/reference_nlvib03.py``: exact flows, root-found switches), which ε = 1e-6 moves by
  about 1e-6.

absorber_jax: ``continuation(system, Harmonic(0.1, 0.8), "omega", bounds=(0.5, 0.8),
direction="down")`` at its defaults (shooting, pseudo-arclength, bifurcations located),
first call (tracing and compilation; the persistent compilation cache off unless
``--cache``) and compiled.  Every time is the best of ``--repeat`` runs (default 3; the
machine is shared and noisy), AUTO's included; the first call is timed once.  Run:

    python scripts/benchmark_auto.py [--eps 1e-3,1e-6] [--ntst 60,100,150,200,300]
                                     [--ntst-ref 400] [--repeat 3] [--cache] [--out FILE]
"""

import os
import sys

if __name__ == "__main__" and "--cache" not in sys.argv:
    os.environ.setdefault("ABSORBER_JAX_CACHE", "0")

import argparse  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
DEFAULT_OUT = os.path.join(ROOT, "docs", "benchmark_auto.txt")
INSTALL = """bifpy (AUTO-07p for Python) is not installed in this environment; this benchmark
needs it and a Fortran compiler:

    apt-get install gfortran
    pip install bifpy

then run  python scripts/benchmark_auto.py  again."""

K = np.array([[1.0, -1.0], [-1.0, 2.0]])
D = 0.03 * K
K_NL, GAP, F_AMP = 100.0, 1.0, 0.1
W_START, W_END = 0.8, 0.5
KINDS = ("fold", "period_doubling", "neimark_sacker")
AUTO_KIND = {"FOLD": "fold", "PERIOD_DOUBLING": "period_doubling",
             "TORUS": "neimark_sacker"}


def load_auto():
    try:
        from bifpy import auto
    except ImportError:
        return None
    return auto


# ---------------------------------------------------------------- AUTO-07p through bifpy

def auto_vector_field(eps):
    """The autonomous vector field of NLvib 03 with the smoothed spring, for bifpy's tracer
    (numpy ufuncs only).  State [q1, q2, v1, v2, s, c]; parameters [Ω, ε, ..., T]."""
    analytic = eps >= 1e-4   # log(1 + exp z) stays finite for |q1 - 1| < 700 ε

    def func(u, p):
        w, e = p[0], p[1]
        q1, q2, v1, v2, s, c = u[0], u[1], u[2], u[3], u[4], u[5]
        z = (q1 - GAP) / e
        if analytic:
            soft = np.log(1.0 + np.exp(z))
        else:
            soft = np.maximum(z, 0.0) + np.log(1.0 + np.exp(-np.abs(z)))
        fnl = K_NL * e * soft
        r2 = s * s + c * c
        a1 = -(K[0, 0] * q1 + K[0, 1] * q2) - (D[0, 0] * v1 + D[0, 1] * v2) - fnl
        a2 = -(K[1, 0] * q1 + K[1, 1] * q2) - (D[1, 0] * v1 + D[1, 1] * v2) + F_AMP * s
        return [v1, v2, a1, a2, s + w * c - s * r2, -w * s + c - c * r2]

    return func, analytic


def auto_start(eps):
    """The linear response at Ω = 0.8 (q1 < 0.2 < the gap: the spring is idle), sampled
    for AUTO's mesh: q = Im(Q e^{iΩt}), Q = (K - Ω² + iΩD)⁻¹ [0, 0.1]."""
    w0 = W_START
    Q = np.linalg.solve(K - w0**2 * np.eye(2) + 1j * w0 * D, np.array([0.0, F_AMP]))
    assert np.max(np.abs(Q)) < 0.9 * GAP

    def stpnt(u, p, tau):
        t = tau * 2 * np.pi / w0
        s, c = np.sin(w0 * t), np.cos(w0 * t)
        u[0] = Q[0].real * s + Q[0].imag * c
        u[1] = Q[1].real * s + Q[1].imag * c
        u[2] = w0 * (Q[0].real * c - Q[0].imag * s)
        u[3] = w0 * (Q[1].real * c - Q[1].imag * s)
        u[4], u[5] = s, c
        p[0], p[1], p[10] = w0, eps, 2 * np.pi / w0

    return stpnt


def run_auto(auto, eps, ntst, nmx=4000):
    func, analytic = auto_vector_field(eps)
    settings = dict(ips=auto.IPS_PERIODIC_ORBIT, ndim=6, npar=2, nmx=nmx, ntst=ntst, ncol=4,
                    iad=3, ilp=1, isp=2, isw=1, nbc=0, nint=0, itmx=8, itnw=7, nwtn=3,
                    jac=1 if analytic else 0, ds=-0.002, dsmin=1e-6, dsmax=0.01,
                    rl0=W_END, rl1=W_START, a0=0.0, a1=1e300, epsl=1e-7, epsu=1e-7,
                    epss=1e-5, npr=100000)
    extra = dict(jac=auto.AUTO_JACOBIAN) if analytic else {}
    t = time.perf_counter()
    res = auto.run(func, auto_start(eps), settings, icu=[1, 11], transpile=True, **extra)
    elapsed = time.perf_counter() - t
    found = {k: [] for k in KINDS}
    npts = 0
    for br in res.branches:
        npts += len(br.points)
        for pt in br.points:
            kind = AUTO_KIND.get(pt.point_type.name)
            if kind:
                found[kind].append(float(pt.parameters[0]))
    return elapsed, {k: sorted(v) for k, v in found.items()}, npts


# ---------------------------------------------------------------- absorber_jax

def nlvib03(aj, eps):
    st = aj.structure_from_matrices(np.eye(2), K, damping=D)
    spring = aj.Contact("x1", gap=GAP, contact=aj.KelvinVoigt(stiffness=K_NL, damping=0.0,
                                                               eps=eps, adhesive=True))
    return aj.StructuralSystem(st, [spring], load="x2", observe="x2")


def run_ours(aj, eps, repeat):
    system = nlvib03(aj, eps)
    times, br = [], None
    for _ in range(1 + repeat):
        t = time.perf_counter()
        br = aj.continuation(system, aj.Harmonic(amplitude=F_AMP, omega=W_START), "omega",
                             bounds=(W_END, W_START), direction="down")
        times.append(time.perf_counter() - t)
    found = {k: sorted(float(b.value) for b in br.of_kind(k)) for k in KINDS}
    seeds = [(float(b.value), np.asarray(b.state)) for b in br.of_kind("neimark_sacker")]
    return times[0], min(times[1:]), found, len(br.values), br.termination, seeds


# ---------------------------------------------------------------- comparison

def worst_error(found, ref):
    """Worst relative distance of the found points from the reference's, and a note when a
    kind's count differs (then each reference point is matched to the nearest found one,
    and the extra ones are counted)."""
    worst, notes = 0.0, []
    for k in KINDS:
        r, f = ref[k], found[k]
        if len(f) != len(r):
            notes.append(f"{len(f)} {k.replace('_', '-')} (exact: {len(r)})")
        if not f:
            worst = np.inf
            continue
        for x in r:
            worst = max(worst, float(np.min(np.abs(np.asarray(f) - x))) / x)
    return worst, "; ".join(notes) or "all six"


def _variational_flow(x, w, eps):
    """State and monodromy after one period of the smoothed field (scipy DOP853)."""
    from scipy.integrate import solve_ivp

    def rhs(t, y):
        q, v, P = y[:2], y[2:4], y[4:].reshape(4, 4)
        z = (q[0] - GAP) / eps
        soft = max(z, 0.0) + np.log1p(np.exp(-abs(z)))
        a = -K @ q - D @ v + np.array([-K_NL * eps * soft, F_AMP * np.sin(w * t)])
        J = np.zeros((4, 4))
        J[:2, 2:] = np.eye(2)
        J[2:, :2] = -K - np.diag([K_NL * 0.5 * (1 + np.tanh(z / 2)), 0.0])
        J[2:, 2:] = -D
        return np.concatenate([v, a, (J @ P).ravel()])

    sol = solve_ivp(rhs, (0.0, 2 * np.pi / w), np.concatenate([x, np.eye(4).ravel()]),
                    method="DOP853", rtol=1e-12, atol=1e-13)
    return sol.y[:4, -1], sol.y[4:, -1].reshape(4, 4)


def _pair_modulus(w, eps, x):
    """``(|μ| - 1, orbit)`` of the period-1 orbit at ``w``, Newton from ``x``, for the
    complex multiplier pair nearest the unit circle."""
    for _ in range(40):
        xT, M = _variational_flow(x, w, eps)
        dx = np.linalg.solve(M - np.eye(4), x - xT)
        x = x + dx
        if np.max(np.abs(dx)) < 1e-12:
            break
    mu = np.linalg.eigvals(_variational_flow(x, w, eps)[1])
    pair = mu[np.abs(mu.imag) > 1e-8]
    return float(pair[np.argmin(np.abs(np.abs(pair) - 1.0))].__abs__() - 1.0), x


def neimark_sacker_reference(eps, guesses):
    """The Neimark–Sacker frequencies by the secant on ``|μ| - 1``, from ``guesses``:
    ``(frequency, state [q1, q2, q1', q2'] at t = 0)`` pairs.  The state only picks which
    of the orbits that coexist there Newton converges to (near the lower point the
    contact-free orbit coexists with the branch's)."""
    out = []
    for w0, x in guesses:
        x = np.asarray(x, float)
        a, b = w0, w0 * (1 + 2e-6)
        ga, x = _pair_modulus(a, eps, x)
        gb, x = _pair_modulus(b, eps, x)
        for _ in range(8):
            c = b - gb * (b - a) / (gb - ga)
            a, ga = b, gb
            b = c
            gb, x = _pair_modulus(b, eps, x)
            if abs(b - a) < 1e-11:
                break
        out.append(b)
    return sorted(out)


def exact_reference():
    sys.path.insert(0, os.path.join(ROOT, "tests"))
    import reference_nlvib03 as ref03

    ex = ref03.continuation()
    return {"fold": sorted(f["Omega"] for f in ex["folds"]),
            "period_doubling": sorted(s["Omega"] for s in ex["stability_changes"]
                                      if s["kind"].startswith("flip")),
            "neimark_sacker": sorted(s["Omega"] for s in ex["stability_changes"]
                                     if s["kind"] == "Neimark-Sacker")}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--eps", default="1e-3,1e-6")
    ap.add_argument("--ntst", default="60,100,150,200,300")
    ap.add_argument("--ntst-ref", type=int, default=400)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--cache", action="store_true",
                    help="keep absorber_jax's persistent compilation cache on (default off)")
    ap.add_argument("--out", default=DEFAULT_OUT)
    a = ap.parse_args()
    auto = load_auto()
    if auto is None:
        print(INSTALL)
        return 0
    import jax

    import absorber_jax as aj

    lines = []

    def out(s=""):
        print(s, flush=True)
        lines.append(s)

    cache = "on" if jax.config.jax_compilation_cache_dir else "off"
    out("## scripts/benchmark_auto.py: continuation vs AUTO-07p (bifpy), NLvib example 03, "
        "0.8 -> 0.5, one process")
    out(f"## {platform.processor() or platform.machine()}, {os.cpu_count()} cores; "
        f"jax {jax.__version__}; absorber_jax's persistent compilation cache {cache}")
    t_over, _, _ = run_auto(auto, 1e-3, 100, nmx=2)
    out(f"## AUTO's fixed cost (tracing, compilation, a two-step run): {t_over:.2f} s")
    for eps in [float(e) for e in a.eps.split(",")]:
        out()
        t1, tc, found, npts, term, ns_seeds = run_ours(aj, eps, a.repeat)
        if eps >= 1e-4:
            t_ref, ref, _ = run_auto(auto, eps, a.ntst_ref)
            _, ref300, _ = run_auto(auto, eps, 300)
            unc = max(abs(x - y) / y for k in KINDS[:2] for x, y in zip(ref300[k], ref[k]))
            auto_ns = ref["neimark_sacker"]
            ref["neimark_sacker"] = neimark_sacker_reference(eps, ns_seeds)
            out(f"### eps = {eps:g}: reference AUTO at NTST = {a.ntst_ref} ({t_ref:.1f} s; "
                f"NTST 300 differs from it by {unc:.1e}) for the folds and period "
                "doublings, scipy shooting for the Neimark-Sacker points (AUTO's differ "
                "from them by " + ", ".join(f"{abs(x - y) / y:.1e}" for x, y in
                                             zip(auto_ns, ref["neimark_sacker"])) + ")")
        else:
            ref = exact_reference()
            out(f"### eps = {eps:g}: reference the exact piecewise-linear continuation "
                "(unsmoothed spring)")
        out("reference: " + ", ".join(f"{k} " + " ".join(f"{x:.8f}" for x in ref[k])
                                        for k in KINDS))
        out(f"{'tool':<40} {'time [s]':>9} {'worst rel. error':>17}  bifurcations found")
        err, note = worst_error(found, ref)
        out(f"{'absorber_jax continuation, compiled':<40} {tc:9.2f} {err:17.1e}  {note} "
            f"({npts} points, {term})")
        out(f"{'absorber_jax, first call (compiles)':<40} {t1:9.2f}")
        rows = []
        for ntst in [int(n) for n in a.ntst.split(",")]:
            runs = [run_auto(auto, eps, ntst) for _ in range(a.repeat)]
            ta, fa, npa = min(runs, key=lambda r: r[0])
            ea, na = worst_error(fa, ref)
            rows.append((ntst, ta, ea))
            out(f"{f'AUTO-07p NTST = {ntst}':<40} {ta:9.2f} {ea:17.1e}  {na} ({npa} points)")
        ok = [(ntst, ta, ea) for ntst, ta, ea in rows if ea <= 2 * err]
        if ok:
            ntst, ta, ea = ok[0]
            out(f"-> equal accuracy: AUTO needs NTST = {ntst} ({ea:.1e}): {ta:.2f} s, "
                f"{ta / tc:.2f}x absorber_jax compiled, {ta / t1:.2f}x its first call")
        else:
            ntst, ta, ea = min(rows, key=lambda r: (r[2], r[1]))
            out(f"-> no AUTO mesh reached absorber_jax's {err:.1e}; its most accurate, "
                f"NTST = {ntst} ({ea:.1e}), took {ta:.2f} s: {ta / tc:.2f}x absorber_jax "
                f"compiled, {ta / t1:.2f}x its first call")
    with open(a.out, "w") as f:
        f.write("\n".join(lines) + "\n")
    print(f"written {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
