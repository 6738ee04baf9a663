"""Benchmark: absorber_jax's harmonic balance against NLvib-py's, in one process, at equal
accuracy against a tight reference.

NLvib-py (https://github.com/julianjurai/NLvib-py, the Python port of the NLvib harmonic
balance toolbox of Krack & Gross; measured at its commit 64ad450, version 0.1.0) is not a
dependency of absorber_jax; install it from a clone (it is not on PyPI):

    git clone https://github.com/julianjurai/NLvib-py /tmp/NLvib-py
    pip install /tmp/NLvib-py

(its ``examples/experiments`` holds large files a checkout may lack; ``pip install`` needs
only ``pyproject.toml`` and ``src/``).  Without it the script says so and exits 0.

Cases, the same model, number of harmonics ``H`` and of time samples ``N`` in both tools
(``N`` = NLvib-py's default for ``H``, the power of 2 at or above 8 (2H + 1): 128 at H = 7,
as in NLvib's example 08):

- **beam**: NLvib example 08, the steel cantilever (2 m, 0.1 m high in bending, 0.3 m
  thick, E = 185 GPa, rho = 7830 kg/m^3) of 8 Hermite elements (16 free DOFs), tanh dry
  friction 1.5 tanh(v / 6e-7) N at the fourth node's deflection ("w3"), 0.2 N at the tip
  ("w8"), D = beta K with 1 % damping in the first mode with "w3" held; the tip's RMS over
  110-370 rad/s, 53 frequencies 5 rad/s apart.
- **2dof**: a tuned absorber with friction to ground: M = diag(1, 0.05) kg,
  K = [[1050, -50], [-50, 50]] N/m, D = 0.002 K, 0.5 tanh(v / eps) N on the absorber
  ("x2", eps = ``--eps2``, default 0.3 m/s), 5 N on the primary ("x1"); the primary's RMS
  over 20-50 rad/s, 61 frequencies 0.5 rad/s apart.  With eps = 1e-3 or 1e-2 m/s NLvib-py's
  fixed-step continuation stops at a step its corrector cannot converge (and with 1e-3
  absorber_jax leaves 24 of the 61 frequencies unconverged from their linear guesses);
  with 3e-2 both converge but the balance converges so slowly in H (1e-3 at H ~ 21-30,
  H = 84 and 120 differing by 6e-5) that no 1e-5 comparison is possible.

The tools:

- **absorber_jax**: ``frequency_response(..., method=HarmonicBalance(harmonics=H,
  samples=N, tol=1e-10), floquet=False)`` on the grid: every frequency from its own linear
  guess, all of them in one vmapped compiled call; the balance condensed onto the friction
  DOF (``condense=True``, the default: 2H + 1 unknowns, the structure through its
  receptances).  Its first call compiles (the persistent compilation cache is off unless
  ``--cache``); the "compiled" time is the best of the next three calls.
- **NLvib-py**: ``hb_residual`` (AFT with ``n_time = N``; its Jacobian by central finite
  differences, column by column, over all n (2H + 1) unknowns) inside
  ``ContinuationSolver.run`` (pseudo-arc-length: tangent predictor, bordered Newton
  corrector) from the top of the band down, as NLvib's example 08 runs, with a fixed step
  equal to the grid spacing (``adapt_step=False``) so that it lands on the grid (its
  unknowns scaled to ~1e-9, so that the arc length is the frequency step); its first point
  by ``scipy.optimize.root`` (hybr, with ``hb_residual``'s Jacobian; NLvib-py's example
  07 starts with scipy's fsolve) from the linear response, the friction linearised as a
  viscous damper f0 / eps.
  Newton tolerance 1e-9 x the force [N] on the residual's 2-norm.  The beam needs
  NLvib-py's finite-difference step patched to 1.5e-15 (``harmonic_balance._FD_STEP``), as
  its example 07 does: the default 1.5e-8 exceeds the displacement coefficients (1e-8 m).
  Where the whole band at some H is predicted to take more than ``--nl-max-band`` seconds
  (from the time of one ``hb_residual`` call and the calls per point at H = 7), NLvib-py
  continues over the peak and two grid points each side only, and its band time is
  extrapolated (first point once, the mean of the others for the rest); absorber_jax is
  then also timed on those points.
- **absorber_jax, full balance** (``--full-balance``, default the 2dof case only): H = 7
  with ``condense=False`` (all DOFs' states balanced, the first guess integrated over
  warm-up periods), for a like-for-like count of unknowns; on the beam the warm-up
  integration through the stiff friction (eps = 6e-7 m/s) did not finish the band within
  400 s (default threads) or 500 s (one thread).

Threads as the libraries choose (``--one-thread``: XLA's Eigen kernels and BLAS on one);
absorber_jax's compiled time is the best of three calls.  Timings on a shared machine vary
with its load: the load average at the start and the end is printed.

Accuracy: the reference is absorber_jax's balance at ``--href`` harmonics (default 84,
N = 2048) on a subset of the grid (the peak and two neighbours each side, seven points
across the band); its uncertainty is its difference to H = href / 2.  For every H of
``--hs``: absorber_jax's band on the subset, and NLvib-py's solve at the peak frequency;
"err at peak" is the relative error of the RMS at the reference's peak frequency, "max
err" the largest on the subset.  For each target of ``--targets`` the H timed for a tool
is the smallest H from which on every listed H meets the target at the peak; the band is
timed at that H per tool, and at H = 7 (NLvib's example 08) for both.

    python scripts/benchmark_nlvib.py [--cases beam,2dof] [--hs 3,5,7,10,15,21,30]
                                      [--targets 1e-3,1e-5] [--href 84] [--eps2 0.3]
                                      [--nl-max-band 120] [--full-balance 2dof]
                                      [--one-thread] [--cache] [--out FILE]

Prints the table and writes it to FILE (default docs/benchmark_nlvib.txt, overwritten).
"""

from __future__ import annotations

import os
import sys

# Before numpy and jax are imported: with --one-thread, XLA's Eigen kernels and BLAS on one
# thread (on the shared 2-core machine, while another job ran, the same compiled call
# once took 0.2 s to 25 s from one run to the next with XLA's default thread pools); and the
# persistent compilation cache off unless --cache, so that a first call pays the whole
# compilation.  (XLA's intra_op_parallelism_threads=1 is not used: a run with it hung.)
if __name__ == "__main__":
    if "--one-thread" in sys.argv:
        for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
            os.environ.setdefault(var, "1")
        os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "")
                                   + " --xla_cpu_multi_thread_eigen=false").strip()
    if "--cache" not in sys.argv:
        os.environ.setdefault("ABSORBER_JAX_CACHE", "0")

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from dataclasses import dataclass, field  # noqa: E402

import numpy as np  # noqa: E402

INSTALL = """NLvib-py is not installed in this environment; this benchmark needs it.
Install it from a clone (it is not on PyPI):

    git clone https://github.com/julianjurai/NLvib-py /tmp/NLvib-py
    pip install /tmp/NLvib-py

then run  python scripts/benchmark_nlvib.py  again."""

HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT_OUT = os.path.join(os.path.dirname(HERE), "docs", "benchmark_nlvib.txt")
AJ_TOL = 1e-10            # absorber_jax HarmonicBalance tol (scaled residual)
NL_TOL_REL = 1e-9         # NLvib-py Newton tolerance, times the force amplitude [N]
BEAM_FD_STEP = 1.5e-15    # NLvib-py's finite-difference step for the beam (its example 07)


def load_nlvib():
    """The NLvib-py names this benchmark uses, or None when it is not installed."""
    try:
        import nlvib
        import nlvib.solvers.harmonic_balance as hbmod
        from nlvib import (
            ContinuationOptions,
            ContinuationSolver,
            FE_EulerBernoulliBeam,
            MechanicalSystem,
            hb_residual,
            tanh_dry_friction,
        )
    except ImportError:
        return None
    return dict(nlvib=nlvib, hbmod=hbmod, ContinuationOptions=ContinuationOptions,
                ContinuationSolver=ContinuationSolver,
                FE_EulerBernoulliBeam=FE_EulerBernoulliBeam,
                MechanicalSystem=MechanicalSystem, hb_residual=hb_residual,
                tanh_dry_friction=tanh_dry_friction)


def nlvib_source():
    """Version of the installed NLvib-py and, when pip recorded a local clone, its commit."""
    from importlib import metadata
    ver = metadata.version("nlvib")
    try:
        url = json.loads(metadata.distribution("nlvib").read_text("direct_url.json"))["url"]
    except Exception:
        return f"nlvib {ver}"
    commit = ""
    if url.startswith("file://"):
        path = url[len("file://"):]
        try:
            commit = subprocess.run(["git", "-C", path, "rev-parse", "HEAD"], check=True,
                                    capture_output=True, text=True).stdout.strip()
        except Exception:
            commit = ""
    return f"nlvib {ver} from {url}" + (f" (commit {commit})" if commit else "")


# ---------------------------------------------------------------------------------------
# The two cases
# ---------------------------------------------------------------------------------------

@dataclass
class Case:
    key: str
    title: str
    M: np.ndarray
    D: np.ndarray
    K: np.ndarray
    dof_names: list
    fric: int                 # index of the friction DOF
    f0: float                 # friction limit force [N]
    eps: float                # tanh regularisation velocity [m/s]
    load: int                 # index of the loaded (and observed) DOF
    force: float              # forcing amplitude [N]
    omegas: np.ndarray        # ascending grid [rad/s]
    fd_step: float | None     # NLvib-py finite-difference step (None: its default)
    aj_system: object = None
    nl_system: object = None
    notes: list = field(default_factory=list)

    @property
    def step(self):
        return float(self.omegas[1] - self.omegas[0])


def beam_case(aj, nl):
    EI, rho_A = 185e9 * 0.3 * 0.1**3 / 12, 7830 * 0.1 * 0.3
    Ms, Ks, names = aj.beam_matrices(8, length=2.0, EI=EI, rho_A=rho_A)
    M, K = Ms.toarray(), Ks.toarray()
    held = [i for i in range(len(names)) if names[i] != "w3"]
    lam = np.linalg.eigvals(np.linalg.solve(M[np.ix_(held, held)], K[np.ix_(held, held)]))
    omega_held = float(np.sqrt(np.min(lam.real)))
    beta = 2 * 0.01 / omega_held
    beam = aj.structure_from_matrices(Ms, Ks, rayleigh=(0.0, beta), dof_names=names)
    damper = aj.FrictionContact("w3", normal_force=1.5,
                                friction=aj.Coulomb(mu=1.0, eps=6e-7))
    system = aj.StructuralSystem(beam, [damper], load="w8", observe="w8")
    case = Case("beam", "NLvib ex. 08 beam, 16 DOF", M, beta * K, K, list(names),
                names.index("w3"), 1.5, 6e-7, names.index("w8"), 0.2,
                np.arange(110.0, 370.0 + 1e-9, 5.0), BEAM_FD_STEP, system)
    # NLvib-py's own beam: its matrices, our damping (its FE beam carries D = 0)
    nb = nl["FE_EulerBernoulliBeam"](n_elements=8, L=2.0, E=185e9, I_area=0.3 * 0.1**3 / 12,
                                      rho=7830.0, A=0.1 * 0.3, bc="clamped-free")
    fric, tip = nb.find_dof(3, "w"), nb.find_dof(8, "w")
    Mn, Kn = nb.M.toarray(), nb.K.toarray()
    dM = np.max(np.abs(Mn - M)) / np.max(np.abs(M))
    dK = np.max(np.abs(Kn - K)) / np.max(np.abs(K))
    assert (fric, tip) == (case.fric, case.load), (fric, tip)
    sysn = nl["MechanicalSystem"](Mn, beta * Kn, Kn)
    sysn.add_nonlinear_element(nl["tanh_dry_friction"](f0=1.5, c=1 / 6e-7, dof_index=fric))
    case.nl_system = sysn
    case.notes.append(f"omega_held = {omega_held:.4f} rad/s, beta = {beta:.6e} s; "
                      f"NLvib-py FE_EulerBernoulliBeam vs aj.beam_matrices: largest relative "
                      f"difference M {dM:.1e}, K {dK:.1e}; friction DOF {fric}, tip DOF {tip}")
    return case


def two_dof_case(aj, nl, eps=0.3):
    M = np.diag([1.0, 0.05])
    K = np.array([[1050.0, -50.0], [-50.0, 50.0]])
    D = 0.002 * K
    st = aj.structure_from_matrices(M, K, damping=D, dof_names=["x1", "x2"])
    damper = aj.FrictionContact("x2", normal_force=0.5, friction=aj.Coulomb(mu=1.0, eps=eps))
    system = aj.StructuralSystem(st, [damper], load="x1", observe="x1")
    case = Case("2dof", "2-DOF friction absorber", M, D, K, ["x1", "x2"], 1, 0.5, eps, 0,
                5.0, np.arange(20.0, 50.0 + 1e-9, 0.5), None, system)
    sysn = nl["MechanicalSystem"](M, D, K)
    sysn.add_nonlinear_element(nl["tanh_dry_friction"](f0=0.5, c=1 / eps, dof_index=1))
    case.nl_system = sysn
    return case


# ---------------------------------------------------------------------------------------
# absorber_jax
# ---------------------------------------------------------------------------------------

def aj_band(aj, case, H, N, omegas, condense=True):
    """(rms, status, seconds, Newton iterations) of absorber_jax's balance on ``omegas``."""
    method = aj.HarmonicBalance(harmonics=H, samples=N, tol=AJ_TOL, condense=condense)
    t0 = time.perf_counter()
    with warnings.catch_warnings():     # failed points: counted from the status instead
        warnings.filterwarnings("ignore", message="frequency_response: .* failed")
        fr = aj.frequency_response(case.aj_system, omegas, amplitude=case.force,
                                   floquet=False, method=method)
        rms, status = np.asarray(fr.rms, float), np.asarray(fr.status)
    return rms, status, time.perf_counter() - t0, np.asarray(fr.iterations)


# ---------------------------------------------------------------------------------------
# NLvib-py
# ---------------------------------------------------------------------------------------

class NLvibBalance:
    """NLvib-py's forced harmonic balance of ``case`` at H harmonics, N samples; counts the
    ``hb_residual`` calls (each returns the residual and its full Jacobian)."""

    def __init__(self, nl, case, H, N, max_calls=100000):
        self.nl, self.case, self.H, self.N = nl, case, H, N
        self.n = case.M.shape[0]
        self.exc = {"dof": case.load, "amplitude": case.force, "harmonic": 1}
        self.calls, self.max_calls = 0, max_calls
        self.tol = NL_TOL_REL * case.force

    def residual(self, Q, omega):
        self.calls += 1
        if self.calls > self.max_calls:
            raise RuntimeError(f"more than {self.max_calls} hb_residual calls")
        hb = self.nl["hbmod"]
        saved = hb._FD_STEP
        if self.case.fd_step is not None:
            hb._FD_STEP = self.case.fd_step
        try:
            return self.nl["hb_residual"](Q, omega, self.case.nl_system, self.H, self.exc,
                                          n_time=self.N)
        finally:
            hb._FD_STEP = saved

    def linear_guess(self, omega):
        """First harmonic of the linear response, the friction linearised (f0/eps)."""
        c = self.case
        Dl = c.D.copy()
        Dl[c.fric, c.fric] += c.f0 / c.eps
        F = np.zeros(self.n)
        F[c.load] = c.force
        X = np.linalg.solve(c.K - omega**2 * c.M + 1j * omega * Dl, F)
        Q = np.zeros(self.n * (2 * self.H + 1))
        Q[self.n:2 * self.n] = X.real          # cos(omega t)
        Q[2 * self.n:3 * self.n] = -X.imag     # sin(omega t)
        return Q

    def point(self, omega):
        """Solve at one frequency from the linear guess: (Q, converged)."""
        from scipy.optimize import root
        Q0 = self.linear_guess(omega)
        s = np.max(np.abs(Q0))                 # solve for Q / s: order-one unknowns

        def fun(y):
            R, J = self.residual(s * y, omega)
            return R, J * s

        sol = root(fun, Q0 / s, jac=True, method="hybr", options={"xtol": 1e-13})
        Q = s * sol.x
        R, _ = self.residual(Q, omega)
        if np.linalg.norm(R) > self.tol:       # polish with plain Newton steps
            for _ in range(10):
                R, J = self.residual(Q, omega)
                if np.linalg.norm(R) <= self.tol:
                    break
                Q = Q - np.linalg.solve(J, R)
        R, _ = self.residual(Q, omega)
        return Q, bool(np.linalg.norm(R) <= self.tol)

    def band(self, omegas):
        """Continuation from max(omegas) down to min(omegas) with a fixed step equal to the
        grid spacing: (omegas reached, rms, converged, seconds, how it ended, seconds of the
        first point's solve)."""
        nl = self.nl
        step = float(omegas[1] - omegas[0])
        t0 = time.perf_counter()
        Q0, ok0 = self.point(float(omegas[-1]))
        t_first = time.perf_counter() - t0
        # continuation parameter lam = -omega (its solver always starts towards larger
        # lam); unknowns y = Q / s, tiny, so that the arc length is the frequency step
        s = 1e9 * max(np.max(np.abs(Q0)), 1e-300)

        def fun(y, lam):
            R, J = self.residual(s * y, -lam)
            return R, J * s

        points = [np.append(Q0 / s, -float(omegas[-1]))]

        def keep(z):
            points.append(np.array(z))

        opts = nl["ContinuationOptions"](
            ds_initial=step, ds_min=step, ds_max=step, adapt_step=False,
            max_steps=len(omegas) + 5, newton_tol=self.tol,
            lambda_max=-float(omegas[0]) - 0.5 * step, callback=keep)
        # with a fixed step its corrector retries a failed step for ever: cap the calls
        self.max_calls = self.calls + 60 * (len(omegas) + 5)
        try:
            res = nl["ContinuationSolver"]().run(fun, Q0 / s, -float(omegas[-1]), opts)
            ok, msg = ok0 and res.converged, res.message
        except RuntimeError as e:
            ok, msg = False, (f"its corrector failed after {-points[-1][-1]:g} rad/s "
                              f"({e}; stopped)")
        dt = time.perf_counter() - t0
        sol = np.array(points)
        return -sol[:, -1], self.rms(s * sol[:, :-1]), ok, dt, msg, t_first

    def rms(self, Q):
        """RMS of the loaded DOF: one value per row of ``Q`` (a float for one ``Q``)."""
        Qm = np.asarray(Q).reshape(-1, 2 * self.H + 1, self.n)[..., self.case.load]
        r = np.sqrt(Qm[..., 0]**2 + 0.5 * np.sum(Qm[..., 1:]**2, axis=-1))
        return float(r[0]) if np.ndim(Q) == 1 else r


# ---------------------------------------------------------------------------------------
# The benchmark
# ---------------------------------------------------------------------------------------

def reference_subset(case, peak_index):
    """Grid indices of the reference: the peak and two neighbours each side, and seven
    points spread over the band."""
    n = len(case.omegas)
    idx = set(range(max(peak_index - 2, 0), min(peak_index + 3, n)))
    idx |= set(np.round(np.linspace(0, n - 1, 7)).astype(int).tolist())
    return np.array(sorted(idx))


def errors(rms_on_subset, ref):
    """(relative error of the RMS at the reference's peak frequency, largest relative error
    on the subset); NaN where a point failed."""
    k = int(np.argmax(ref))
    return (abs(rms_on_subset[k] / ref[k] - 1),
            float(np.max(np.abs(rms_on_subset / ref - 1))))


def chosen_h(hs, errs, target):
    """Smallest H from which on every listed H meets ``target`` (None: none does)."""
    ok = [e <= target for e in errs]
    for i in range(len(hs)):
        if all(ok[i:]):
            return hs[i]
    return None


def fmt_t(t):
    return f"{t:.3g} s" if t >= 0.01 else f"{t * 1e3:.3g} ms"


def samples(H):
    """NLvib-py's default number of time samples for H harmonics, the next power of 2 at or
    above 8 (2H + 1): 128 at H = 7 (example 08's)."""
    return int(2 ** np.ceil(np.log2(8 * (2 * H + 1))))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", default="beam,2dof")
    ap.add_argument("--hs", default="3,5,7,10,15,21,30")
    ap.add_argument("--targets", default="1e-3,1e-5")
    ap.add_argument("--href", type=int, default=84)
    ap.add_argument("--eps2", type=float, default=0.3,
                    help="tanh velocity of the 2-DOF case [m/s] (default 0.3)")
    ap.add_argument("--nl-max-band", type=float, default=120.0,
                    help="predicted NLvib-py band time [s] above which it continues over "
                         "the peak and two points each side only (default 120)")
    ap.add_argument("--full-balance", default="2dof",
                    help="cases where absorber_jax is also timed at H = 7 with "
                         "condense=False (default 2dof; on the beam its warm-up "
                         "integration did not finish the band within 400 s)")
    ap.add_argument("--one-thread", action="store_true",
                    help="XLA's Eigen kernels and BLAS on one thread (default: as the "
                         "libraries choose)")
    ap.add_argument("--cache", action="store_true",
                    help="keep absorber_jax's persistent compilation cache on (default off: "
                         "first calls compile from scratch)")
    ap.add_argument("--out", default=DEFAULT_OUT)
    a = ap.parse_args()

    nl = load_nlvib()
    if nl is None:
        print(INSTALL)
        return 0
    import jax

    import absorber_jax as aj

    hs = sorted(int(h) for h in a.hs.split(","))
    targets = [float(t) for t in a.targets.split(",")]
    lines = []

    def out(s=""):
        print(s, flush=True)
        lines.append(s)

    out("## scripts/benchmark_nlvib.py: absorber_jax harmonic balance vs NLvib-py, "
        "in one process")
    out(f"## {platform.machine()}, {os.cpu_count()} cores, load average at the start "
        f"{os.getloadavg()[0]:.2f}; python {platform.python_version()}, numpy {np.__version__}"
        f", jax {jax.__version__} ({jax.local_device_count()} {jax.devices()[0].platform} "
        f"device); {nlvib_source()}")
    threads = ("one (XLA_FLAGS --xla_cpu_multi_thread_eigen=false, "
               "OPENBLAS/OMP/MKL_NUM_THREADS=1)" if a.one_thread else "as the libraries choose")
    cache = "on" if jax.config.jax_compilation_cache_dir else "off"
    out(f"## threads: {threads}; absorber_jax's persistent compilation cache {cache}")
    builders = {"beam": beam_case, "2dof": lambda aj, nl: two_dof_case(aj, nl, a.eps2)}
    wall0 = time.perf_counter()
    for key in a.cases.split(","):
        case = builders[key](aj, nl)
        om = case.omegas
        out()
        out(f"### case {case.key}: {case.title}; tanh velocity {case.eps:g} m/s; "
            f"{len(om)} frequencies {om[0]:g}-{om[-1]:g} rad/s, step {case.step:g}")
        for note in case.notes:
            out(f"- {note}")

        # -- absorber_jax on the band at every H (the first call of each H compiles)
        aj_first = {}
        for H in hs:
            rms, st, t, it = aj_band(aj, case, H, samples(H), om)
            aj_first[H] = dict(rms=rms, status=st, t=t, it=it)
        pk = int(np.nanargmax(aj_first[hs[-1]]["rms"]))
        sub = reference_subset(case, pk)

        # -- the reference on a subset of the grid
        h2 = a.href // 2
        ref, st_ref, t_ref, _ = aj_band(aj, case, a.href, samples(a.href), om[sub])
        ref2, _, _, _ = aj_band(aj, case, h2, samples(h2), om[sub])
        ref_unc = float(np.max(np.abs(ref2 / ref - 1)))
        out(f"- reference: absorber_jax H = {a.href} (N = {samples(a.href)}) at "
            f"{len(sub)} frequencies {', '.join(f'{w:g}' for w in om[sub])}; "
            f"{int(np.sum(st_ref != 0))} failed, {fmt_t(t_ref)} with compilation; peak RMS "
            f"{np.max(ref):.8e} m at {om[sub][np.argmax(ref)]:g} rad/s; H = {h2} "
            f"(N = {samples(h2)}) differs from it by at most {ref_unc:.1e}")

        # -- errors per H: absorber_jax's band; NLvib-py's solve at the peak frequency
        om_pk = float(om[sub][np.argmax(ref)])
        i_pk = int(np.flatnonzero(om == om_pk)[0])
        out(f"- relative error of the RMS at the peak ({om_pk:g} rad/s) / largest on the "
            f"reference's frequencies (absorber_jax: its band; NLvib-py: a solve at the peak "
            f"frequency from the linear guess, as its continuation starts):")
        aj_err, nl_err, t_call = [], [], {}
        for H in hs:
            e_aj = errors(aj_first[H]["rms"][sub], ref)
            bal = NLvibBalance(nl, case, H, samples(H))
            t0 = time.perf_counter()
            Q, conv = bal.point(om_pk)
            t_pt = time.perf_counter() - t0
            t_call[H] = t_pt / bal.calls
            r_nl = bal.rms(Q)
            e_nl = abs(r_nl / np.max(ref) - 1) if conv else np.inf
            e_aj0 = e_aj[0] if np.isfinite(e_aj[0]) else np.inf
            aj_err.append(e_aj0)
            nl_err.append(e_nl)
            d = abs(r_nl / aj_first[H]["rms"][i_pk] - 1)
            it = aj_first[H]["it"]
            out(f"  H = {H:3d}, N = {samples(H):4d}: absorber_jax {e_aj[0]:.2e} / "
                f"{e_aj[1]:.2e} ({int(np.sum(aj_first[H]['status'] != 0))} of {len(om)} "
                f"failed, Newton steps median {np.median(it):.0f} max {np.max(it)}, band "
                f"{fmt_t(aj_first[H]['t'])} with compilation) | NLvib-py {e_nl:.2e} "
                f"({'converged' if conv else 'NOT converged'}, {fmt_t(t_pt)}, {bal.calls} "
                f"hb_residual calls, {fmt_t(t_call[H])} each) | the two differ by {d:.1e}")

        # -- the H to time, per target and tool, and H = 7 (NLvib's example 08)
        picks = {tgt: (chosen_h(hs, aj_err, tgt), chosen_h(hs, nl_err, tgt))
                 for tgt in targets}
        aj_h = sorted({p[0] for p in picks.values() if p[0] is not None} | {7})
        nl_h = sorted({p[1] for p in picks.values() if p[1] is not None} | {7})

        aj_timed = {}
        for H in aj_h:
            first = aj_first[H]["t"] if H in aj_first else aj_band(aj, case, H, samples(H),
                                                                   om)[2]
            rms, st, t2, _ = aj_band(aj, case, H, samples(H), om)          # compiled
            t2 = min(t2, *(aj_band(aj, case, H, samples(H), om)[2] for _ in range(2)))
            aj_timed[H] = dict(rms=rms, status=st, first=first, t=t2)
        nl_runs, calls_per_point = {}, 15.0
        part = om[max(i_pk - 2, 0):i_pk + 3]
        for H in nl_h:                       # H = 7 first: it measures calls per point
            predicted = t_call.get(H, 0.0) * calls_per_point * len(om)
            grid = om if predicted <= a.nl_max_band else part
            bal = NLvibBalance(nl, case, H, samples(H))
            omn, rmsn, ok, tn, msg, t1 = bal.band(grid)
            near = np.abs(omn[:, None] - om[None, :]) < 1e-6 * case.step
            on = np.any(near, axis=1)
            rms_grid = np.full(len(om), np.nan)
            rms_grid[np.argmax(near, axis=1)[on]] = rmsn[on]
            offgrid = float(np.max(np.min(np.abs(omn[:, None] - om[None, :]), axis=1)))
            nl_runs[H] = dict(rms=rms_grid, points=len(omn), ok=ok, t=tn, msg=msg,
                              calls=bal.calls, covered=int(on.sum()), offgrid=offgrid,
                              partial=grid is not om, predicted=predicted, grid=grid,
                              t_first=t1)
            if H == 7 and grid is om and ok:
                calls_per_point = bal.calls / len(omn)

        out("- the band, timed (absorber_jax: compiled, the best of 3 calls (2 for the full "
            "balance); [its 1st call, with compilation]); errors against the reference on "
            "its frequencies:")
        out(f"  {'case':5s} {'target':>7s} {'tool':13s} {'H':>3s} {'points':>6s} "
            f"{'time':>17s} {'time/point':>10s} {'err@peak':>9s} {'max err':>9s}  "
            f"NLvib-py / absorber_jax")
        for tgt in [None] + targets:
            if tgt is None:
                label, (h_aj, h_nl) = "H=7", (7, 7)
            else:
                label, (h_aj, h_nl) = f"{tgt:.0e}", picks[tgt]
            if h_aj is None or h_nl is None:
                out(f"  {case.key:5s} {label:>7s} no listed H reaches it (absorber_jax: "
                    f"{h_aj}, NLvib-py: {h_nl})")
                continue
            A, B = aj_timed[h_aj], nl_runs[h_nl]
            ea = errors(A["rms"][sub], ref)
            have = np.isfinite(B["rms"][sub])
            eb = errors(B["rms"][sub][have], ref[have]) if have.any() else (np.nan, np.nan)
            # a partial band: its first point's solve once, its other points' mean time for
            # the rest of the band
            tot = (B["t"] if not B["partial"] else B["t_first"] + (B["t"] - B["t_first"])
                   * (len(om) - 1) / max(B["points"] - 1, 1))
            ratio_pt = (tot / len(om)) / (A["t"] / len(om))
            out(f"  {case.key:5s} {label:>7s} {'absorber_jax':13s} {h_aj:3d} {len(om):6d} "
                f"{fmt_t(A['t']):>8s} [{fmt_t(A['first']):>6s}] "
                f"{fmt_t(A['t'] / len(om)):>10s} {ea[0]:9.1e} {ea[1]:9.1e}")
            if B["partial"]:
                if ("part", h_aj) not in aj_timed:      # absorber_jax on the same points
                    first = aj_band(aj, case, h_aj, samples(h_aj), part)[2]
                    t2 = min(aj_band(aj, case, h_aj, samples(h_aj), part)[2]  # compiled
                             for _ in range(3))
                    aj_timed[("part", h_aj)] = dict(first=first, t=t2)
                P = aj_timed[("part", h_aj)]
                out(f"  {case.key:5s} {label:>7s} {'NLvib-py':13s} {h_nl:3d} {B['points']:6d} "
                    f"{fmt_t(B['t']):>17s} {fmt_t(B['t'] / B['points']):>10s} {eb[0]:9.1e} "
                    f"{eb[1]:9.1e}  {len(om)} points extrapolated: {fmt_t(tot)}, "
                    f"{ratio_pt:.0f}x")
                out(f"  {case.key:5s} {label:>7s} {'absorber_jax':13s} {h_aj:3d} "
                    f"{len(part):6d} {fmt_t(P['t']):>8s} [{fmt_t(P['first']):>6s}] "
                    f"{fmt_t(P['t'] / len(part)):>10s} {'':9s} {'':9s}  on NLvib-py's "
                    f"points: {B['t'] / P['t']:.0f}x")
            else:
                out(f"  {case.key:5s} {label:>7s} {'NLvib-py':13s} {h_nl:3d} {B['points']:6d} "
                    f"{fmt_t(B['t']):>17s} {fmt_t(B['t'] / B['points']):>10s} {eb[0]:9.1e} "
                    f"{eb[1]:9.1e}  {B['t'] / A['t']:.0f}x total, {ratio_pt:.0f}x per point")
        if case.key in a.full_balance.split(","):
            first = aj_band(aj, case, 7, samples(7), om, condense=False)[2]
            rms, st, t2, it = aj_band(aj, case, 7, samples(7), om, condense=False)
            t2 = min(t2, aj_band(aj, case, 7, samples(7), om, condense=False)[2])
            ea = errors(rms[sub], ref)
            B = nl_runs[7]
            nfail = int(np.sum(st != 0))
            out(f"  {case.key:5s} {'H=7':>7s} {'aj, full':13s} {7:3d} {len(om):6d} "
                f"{fmt_t(t2):>8s} [{fmt_t(first):>6s}] {fmt_t(t2 / len(om)):>10s} "
                f"{ea[0]:9.1e} {ea[1]:9.1e}  "
                + (f"NLvib-py H = 7 band / this: {B['t'] / t2:.2g}x" if not B["partial"]
                   else "")
                + f"  (condense=False: all {case.M.shape[0]} DOFs balanced, first guess "
                f"integrated; {nfail} failed, Newton steps median {np.median(it):.0f})")
        for H in nl_h:
            B = nl_runs[H]
            how = (f"over {B['grid'][-1]:g}-{B['grid'][0]:g} rad/s only (the whole band "
                   f"predicted {B['predicted']:.0f} s > --nl-max-band)" if B["partial"]
                   else "over the band")
            line = (f"- NLvib-py H = {H} {how}: {B['points']} points ({B['covered']} on the "
                    f"grid, farthest {B['offgrid']:.1e} rad/s off it), {B['calls']} "
                    f"hb_residual calls ({B['calls'] / B['points']:.1f} per point), ended: "
                    f"{B['msg']}{'' if B['ok'] else ' [NOT CONVERGED]'}")
            if H in aj_timed:
                both = np.isfinite(B["rms"])
                d = float(np.max(np.abs(B["rms"][both] / aj_timed[H]["rms"][both] - 1)))
                line += (f"; it and absorber_jax's band at H = {H} differ by at most "
                         f"{d:.1e} (relative RMS) on its points")
            out(line)
    out()
    out(f"## total wall time {time.perf_counter() - wall0:.0f} s; load average at the end "
        f"{os.getloadavg()[0]:.2f}")
    if a.out:
        os.makedirs(os.path.dirname(os.path.abspath(a.out)), exist_ok=True)
        with open(a.out, "w") as f:
            f.write("\n".join(lines) + "\n")
        print(f"written to {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
