"""Attractor maps: many initial conditions marched at once, the distinct responses they
settle on, and the statistics a designer needs for each, periodic or not.

At one forcing, ``K`` initial states (sampled in a box around rest, or given) are marched in
one vmapped call (``Marching``: the Poincaré samples ``t = kT`` until they repeat with
a period ``n <= n_max``).  Then every lane is integrated over a further window of
``window`` periods from where it ended, sampled ``S`` times per period (``S = SAMPLES``, or
more for a system with contacts: see ``samples_per_period``): the largest
``|observable|`` (``peak``), its RMS and half peak-to-peak over the window, the spread of
the Poincaré samples (their largest distance from their mean, on the scaled state): zero
for a periodic response, finite for a quasi-periodic or chaotic one, and the impacts per
period: the times a contact wall closes (``system.penetrations`` turning positive between
two samples), counted over the window and divided by ``window``.  The sampling resolves a
contact: ``S`` puts at least ``CONTACT_SAMPLES`` samples into the half period of the
contact's own oscillation (``π / system.stiffness_rate()``, an upper bound on the rate, so a
lower bound on the contact time).

The largest Lyapunov exponent ``λ`` [1/s] tells a chaotic response (``λ > 0``) from a
quasi-periodic one (``λ ≈ 0``) and a stable orbit (``λ = ln|μ|max / nT < 0``, ``μ`` its
Floquet multipliers; ``≈ 0`` on a floating absorber's neutral family): a tangent vector
carried period by period over the window by the flow's derivative (steps controlled on the
tangent too), renormalised each period, its log growth averaged over the last
``window - window // 4`` periods (the first quarter lets it align with the growing
direction).  A non-periodic attractor is called chaotic when ``λ`` exceeds
``CHAOS_MARGIN / (window T)``: a neutral direction (a floating absorber, the angle on a
torus) grows at most polynomially, which biases the finite-window estimate by about
``ln(4) / (0.75 window T)``; else quasi-periodic.  Lanes are grouped into
attractors by period multiple and window statistics; each attractor carries its share of the
sampled initial states.  So a design has a number (the peak over the window) even where no
periodic orbit is stable.

Orbits that differ only by a symmetry (a mirrored impacting orbit in a symmetric clearance)
or by the free position of a floating absorber are one attractor here: they have the same
statistics.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core import tables
from .._core.checks import check_scalar, require_x64
from .._core.devices import over_lanes
from .._core.legacy import no_more
from .._core.status import Status
from .._core.units import Signals, signals_of
from .._integration.flow import flow_along, make_config, state_scale
from .._integration.settings import integrator_from
from .._systems.base import AbstractSystem, is_hybrid
from .._systems.forcing import AbstractPeriodicForcing
from .marching import Marching
from .orbit import SteadyState, contact_statistics, parabolic_peak
from .steady import check_system_and_forcing, method_from, solve_point

# samples per forcing period of the statistics window (at least)
SAMPLES = 64
# samples per shortest contact time (a half period of the contact's oscillation), and the cap
# on the samples per forcing period that this asks for
CONTACT_SAMPLES = 4
MAX_SAMPLES = 2048
# a non-periodic response is chaotic when its largest Lyapunov exponent exceeds this many
# 1 / (window T) (the module docstring says why)
CHAOS_MARGIN = 10.0
# stroboscopic samples of the observable repeating to this fraction of its amplitude make a
# period
PERIOD_TOL = 1e-3


class Attractor(eqx.Module):
    """One response found by [`attractors`][absorber_jax.attractors].

    ``periodic``: a period-``period_multiple`` orbit: the observable's stroboscopic
    samples over the window repeat after ``period_multiple`` periods and ``lyapunov`` is
    below the chaos threshold (else quasi-periodic or chaotic, or not settled within the
    marching budget); ``kind``: ``"periodic"``, ``"quasi-periodic"`` or
    ``"chaotic"`` (a non-periodic response is chaotic when ``lyapunov`` exceeds
    ``10 / (window T)``, ``T`` the forcing period: a neutral direction, such as a floating
    absorber or the angle on a torus, biases the finite-window estimate by about
    ``ln(4) / (0.75 window T)``; ``"not periodic"`` when the exponent could not be
    computed); ``share``: fraction of the sampled initial states
    that settled on it; ``amplitude``, ``rms``, ``peak``: the observable's half
    peak-to-peak, RMS and largest ``|value|`` over the window; ``spread``: the Poincaré
    samples' largest distance from their mean (scaled state; ~0 for an orbit);
    ``impacts``: contact closures per forcing period over the window (0 without contact);
    ``lyapunov``: the largest Lyapunov exponent [1/s] over the window (a tangent vector
    carried period by period by the flow's derivative, renormalised each period, its log
    growth averaged over the last three quarters of the window; > 0 chaotic, ≈ 0
    quasi-periodic, ``ln|μ|max / nT < 0`` on a stable orbit; the median over the members);
    ``converged``: marching's periodicity test passed for one of its members (not for a
    floating absorber's neutral family, whose position drifts slowly: its ``stable`` is then
    False, not proven); ``stable``: the Floquet label of that member; ``multipliers``;
    ``state``: public state on it at ``t = 0 mod T`` (one member); ``members``: indices of
    its initial states."""

    periodic: bool = eqx.field(static=True)
    kind: str = eqx.field(static=True)
    period_multiple: int = eqx.field(static=True)
    converged: bool = eqx.field(static=True)
    share: float
    amplitude: float
    rms: float
    peak: float
    spread: float
    impacts: float
    lyapunov: float
    stable: bool = eqx.field(static=True)
    multipliers: np.ndarray
    state: np.ndarray
    members: np.ndarray

    def summary(self):
        """The attractor as a JSON-ready dict of its scalar fields (``members`` as a count)."""
        return dict(kind=self.kind, periodic=self.periodic,
                    period_multiple=self.period_multiple,
                    converged=self.converged,
                    share=float(self.share), amplitude=float(self.amplitude),
                    rms=float(self.rms), peak=float(self.peak), spread=float(self.spread),
                    impacts=float(self.impacts), lyapunov=float(self.lyapunov),
                    stable=self.stable, members=int(len(self.members)))


class AttractorMap(eqx.Module):
    """The responses reached from ``initial_states`` at one forcing
    ([`attractors`][absorber_jax.attractors]).

    ``steady``: the marching result per initial state (batched
    [`SteadyState`][absorber_jax.SteadyState]; status ``NOT_PERIODIC`` where the response never
    repeats); ``peak``, ``rms``, ``amplitude``, ``spread``, ``impacts`` (per forcing period),
    ``lyapunov`` [1/s]: window statistics per initial state;
    ``section``: the observable at ``t = kT`` over the window (``(K, window)``: the
    stroboscopic samples a bifurcation diagram plots); ``label``: the attractor index of each
    initial state; ``attractors``: the distinct [`Attractor`][absorber_jax.Attractor]s, most
    frequent first; ``signals``: the names and SI units of what the statistics measure (the
    observable, the state components), as the CSV headers and ``to_xarray`` attributes give
    them."""

    omega: float
    amplitude_F0: float
    initial_states: np.ndarray
    steady: SteadyState
    peak: np.ndarray
    rms: np.ndarray
    amplitude: np.ndarray
    spread: np.ndarray
    impacts: np.ndarray
    lyapunov: np.ndarray
    section: np.ndarray
    label: np.ndarray
    attractors: tuple
    signals: Signals = eqx.field(static=True, default=Signals())

    def periods(self):
        """The period multiple of the response reached from each initial state, that of the
        attractor it belongs to (0 where that attractor is not periodic): what the
        bifurcation diagram colours each state's samples by, so that it and ``attractors``
        never disagree."""
        return np.array([a.period_multiple if a.periodic else 0
                         for a in (self.attractors[int(j)] for j in self.label)], dtype=int)

    def summary(self):
        """The map as a JSON-ready dict: forcing, number of initial states, and each
        attractor's ``summary()``."""
        return dict(omega=float(self.omega), F0=float(self.amplitude_F0),
                    samples=int(self.label.shape[0]),
                    attractors=[a.summary() for a in self.attractors])

    def failures(self):
        """``[(index, what failed and what to try)]`` of the initial states whose marching
        did not settle on a periodic orbit (``NOT_PERIODIC``: quasi-periodic or chaotic
        responses too, whose window statistics still hold)."""
        return tables.failure_list(self.steady.status)

    def to_csv(self, path):
        """One row per initial state, SI values, each header with its unit: ``omega``, the
        initial state, the attractor it settled on, the window statistics, the marching
        status."""
        tables.write_csv(path, tables.attractor_columns(self))

    def to_dataframe(self):
        """The rows of ``to_csv`` as a ``pandas.DataFrame`` (needs pandas)."""
        return tables.dataframe(tables.attractor_columns(self), "AttractorMap.to_dataframe")

    def to_xarray(self):
        """An ``xarray.Dataset`` over the initial states (``sample``): initial states,
        window statistics and stroboscopic samples with ``units`` and ``long_name``, the
        attractor labels, the marching status with its code names, the distinct attractors
        over ``attractor`` (needs xarray)."""
        return tables.attractor_dataset(self)


def samples_per_period(system, omega):
    """Samples per forcing period of the statistics window: ``SAMPLES``, or for a system with
    contacts enough to put ``CONTACT_SAMPLES`` samples into the shortest contact time
    ``π / system.stiffness_rate()`` (a multiple of ``SAMPLES``, at most ``MAX_SAMPLES``)."""
    if system.penetrations(system.rest_state()).shape[0] == 0:
        return SAMPLES
    rate = float(system.stiffness_rate())
    need = 2.0 * CONTACT_SAMPLES * rate / float(omega) if np.isfinite(rate) else MAX_SAMPLES
    return int(min(MAX_SAMPLES, SAMPLES * max(1, int(np.ceil(need / SAMPLES)))))


def window_statistics(system, forcing, x, window, samples, cfg):
    """The scaled state over ``window`` periods from ``x``, ``samples`` per period
    (``(window * samples + 1, n)``, both ends included), the integrator's status, and the
    largest Lyapunov exponent [1/s] (module docstring): one integration carrying the
    state and one tangent, period by period (the tangent renormalised each period)."""
    T = 2 * jnp.pi / forcing.omega
    skip = window // 4
    ts = T * jnp.arange(1, samples + 1) / samples
    v0 = jnp.ones_like(x) / jnp.sqrt(x.shape[0])

    def period(c, k):
        y, v, acc, st = c
        ys, vs, s = flow_along((system, forcing), y, v, T, ts, cfg)
        size = jnp.linalg.norm(vs[-1])
        acc = acc + jnp.where(k >= skip, jnp.log(size), 0.0)
        st = jnp.where(st == Status.SUCCESS, s, st)
        return (ys[-1], vs[-1] / size, acc, st), ys

    c0 = (x, v0, jnp.zeros((), x.dtype), jnp.asarray(Status.SUCCESS))
    (_, _, acc, st), ys = jax.lax.scan(period, c0, jnp.arange(window))
    ys = jnp.concatenate([x[None], ys.reshape(-1, x.shape[0])])
    return ys, st, acc / ((window - skip) * T)


@eqx.filter_jit
def _march_all(system, forcing, x0s, cfg, method, window, samples):
    scale = state_scale(system, forcing)

    def lane(x0):
        ss = solve_point(system, forcing, method, cfg, guess=x0)
        x = system.to_internal(ss.state) / scale
        ys, st, lyap = window_statistics(system, forcing, x, window, samples, cfg)
        s = ys * scale
        impacts, _ = contact_statistics(system, forcing, x, s, window, cfg, window,
                                        cyclic=False)
        s, ys = s[:-1], ys[:-1]
        obs = jax.vmap(system.observable)(s)
        sec = ys[::samples]
        spread = jnp.max(jnp.linalg.norm(sec - jnp.mean(sec, axis=0), axis=1))
        hi = parabolic_peak(obs, jnp.argmax(obs))
        lo = parabolic_peak(obs, jnp.argmin(obs))
        # the period seen in the window: the smallest n whose stroboscopic samples of the
        # observable repeat to PERIOD_TOL of its amplitude (a floating absorber's orbit
        # family settles too slowly for marching's tail test, but repeats here)
        osec = obs[::samples]
        ns = jnp.arange(1, method.n_max + 1)
        d = jnp.stack([jnp.max(jnp.abs(osec[n:] - osec[:-n]))
                       for n in range(1, method.n_max + 1)])
        rep = d <= PERIOD_TOL * 0.5 * (hi - lo)
        period = jnp.where(jnp.any(rep), ns[jnp.argmax(rep)], 0)
        ok = (st == Status.SUCCESS) & jnp.all(jnp.isfinite(ys))
        nan = jnp.nan
        stats = (jnp.where(ok, jnp.maximum(hi, -lo), nan),
                 jnp.where(ok, jnp.sqrt(jnp.mean(obs**2)), nan),
                 jnp.where(ok, 0.5 * (hi - lo), nan),
                 jnp.where(ok, spread, nan),
                 jnp.where(ok, obs[::samples], nan),
                 jnp.where(ok, period, -1),
                 jnp.where(ok, impacts, nan),
                 jnp.where(ok & jnp.isfinite(lyap), lyap, nan))
        return ss, stats

    return over_lanes(lane, is_hybrid(system))(x0s)


def _sample_states(system, forcing, samples, spread, seed):
    scale = np.asarray(state_scale(system, forcing))
    rest = np.asarray(system.rest_state())
    rng = np.random.default_rng(seed)
    u = rng.uniform(-1.0, 1.0, size=(samples, scale.size))
    x_int = rest + spread * scale * u
    return np.stack([np.asarray(system.to_public(jnp.asarray(x))) for x in x_int])


def attractors(system: AbstractSystem, forcing: AbstractPeriodicForcing, *, initial_states=None,
               samples=32, spread=3.0, seed=0, method=None, integrator=None, window=40,
               rel_tol=2e-3, resolution=None, **legacy) -> AttractorMap:
    """The distinct responses of ``system`` under ``forcing`` reached from many initial
    states (see the module docstring).

    **Arguments**

    - ``initial_states``: ``(K, num_states)`` public states; default ``samples`` states
      uniform in a box of ``±spread`` state scales around rest (``seed``).
    - ``method``: the ``Marching`` every lane runs, default ``Marching(n_max=8,
      max_periods=2000, tol=1e-6)`` (period multiples recognised, budget in forcing periods,
      recurrence tolerance on the scaled state).  Its ``give_up``, the periods after which a
      lane that is not settling stops marching, defaults here to ``max_periods // 4``: a map
      whose lanes are all chaotic then costs a quarter of the budget
      (``give_up=max_periods`` marches every lane to the end of the budget; a transient chaos
      longer than ``give_up`` periods that ends on a periodic orbit is otherwise reported as
      not periodic).
    - ``integrator``: an ``Integrator`` (default: the periodic tolerances).
    - ``window``: periods of the statistics window after marching.
    - ``resolution``: samples per forcing period over the window; default
      ``samples_per_period`` (enough to count the impacts of the stiffest contact).
    - ``rel_tol``: two lanes are one attractor when their period multiples agree and their
      window amplitude and RMS agree to ``rel_tol`` (non-periodic: 5 %).

    **Returns** an ``AttractorMap``.
    """
    require_x64("attractors")
    check_system_and_forcing(system, forcing, "attractors")
    method = method_from(method, "attractors", legacy,
                         default=Marching(n_max=8, max_periods=2000, tol=1e-6))
    if not isinstance(method, Marching):
        raise ValueError(f"attractors.method must be an aj.Marching(...), got "
                         f"{type(method).__name__}")
    if method.give_up is None:
        method = dataclasses.replace(method, give_up=max(1, method.max_periods // 4))
    integ = integrator_from(integrator, "periodic", "attractors", legacy)
    no_more("attractors", legacy)
    n_max = method.n_max
    # the window must show a period-n_max orbit repeating at least once
    for name, v, lo in (("samples", samples, 1), ("window", window, max(2, n_max + 1))):
        if not isinstance(v, int) or v < lo:
            raise ValueError(f"attractors: {name} must be an integer >= {lo}"
                             + (" (n_max + 1)" if name == "window" else "") + f", got {v!r}")
    check_scalar("attractors", "spread", spread, lo=0.0, lo_open=True)
    check_scalar("attractors", "rel_tol", rel_tol, lo=0.0, hi=1.0, lo_open=True)
    if resolution is None:
        resolution = samples_per_period(system, forcing.omega)
    elif not isinstance(resolution, int) or resolution < 2:
        raise ValueError(f"attractors: resolution must be an integer >= 2 (samples per "
                         f"period), got {resolution!r}")
    if initial_states is None:
        y0 = _sample_states(system, forcing, samples, float(spread), seed)
    else:
        y0 = np.atleast_2d(np.asarray(initial_states, dtype=float))
        if y0.ndim != 2 or y0.shape[1] != system.num_states:
            raise ValueError(f"initial_states must have shape (K, {system.num_states}) "
                             f"({', '.join(system.state_names)}), got {y0.shape}")
        if not np.all(np.isfinite(y0)):
            raise ValueError("initial_states must be finite")
    cfg = make_config(system, forcing, integ.solver, integ.rtol, integ.atol, integ.max_steps)
    x0s = jnp.stack([system.to_internal(jnp.asarray(y)) for y in y0])
    ss, stats = _march_all(system, forcing, x0s, cfg, method, int(window), resolution)
    ss = jax.tree_util.tree_map(np.asarray, ss)
    peak, rms, amp, spr, sec, per, imp, lyap = (np.asarray(a) for a in stats)
    # an observable that repeats while the motion diverges from its neighbours (a primary
    # near resonance carrying a chattering ball: the primary's stroboscopic samples repeat
    # to PERIOD_TOL, the ball's do not) is not a periodic attractor: chaotic, as λ says
    chaos = CHAOS_MARGIN * float(forcing.omega) / (2 * np.pi * window)
    per = np.where((per > 0) & (lyap > chaos), 0, per)
    label, groups = _group(per, amp, rms, rel_tol)
    found = []
    K = y0.shape[0]
    for g in groups:
        # a representative: one whose marching converged, if any
        conv = [j for j in g if int(ss.status[j]) == Status.SUCCESS]
        i = conv[0] if conv else g[0]
        periodic = int(per[i]) > 0
        lam = float(np.median(lyap[g]))
        chaotic = lam > chaos
        kind = ("periodic" if periodic else "not periodic" if not np.isfinite(lam)
                else "chaotic" if chaotic else "quasi-periodic")
        found.append(Attractor(
            periodic=periodic, kind=kind, period_multiple=int(per[i]), converged=bool(conv),
            share=len(g) / K, amplitude=float(np.median(amp[g])), rms=float(np.median(rms[g])),
            peak=float(np.max(peak[g])), spread=float(np.max(spr[g])),
            impacts=float(np.median(imp[g])), lyapunov=lam,
            stable=bool(ss.stable[i]),
            multipliers=np.asarray(ss.multipliers[i]), state=np.asarray(ss.state[i]),
            members=np.asarray(g)))
    return AttractorMap(omega=float(forcing.omega), amplitude_F0=float(forcing.amplitude),
                        initial_states=y0, steady=ss, peak=peak, rms=rms, amplitude=amp,
                        spread=spr, impacts=imp, lyapunov=lyap, section=sec, label=label,
                        attractors=tuple(found), signals=signals_of(system))


def _group(per, amp, rms, rel_tol):
    """Lanes grouped by the period seen in the window (0: not periodic) and window
    amplitude/RMS; groups sorted by size.  Lanes whose window failed get label -1."""
    K = amp.shape[0]
    label = np.full(K, -1)
    groups = []
    reps = []
    for i in range(K):
        if not (np.isfinite(amp[i]) and np.isfinite(rms[i])):
            continue
        n = int(per[i])
        periodic = n > 0
        tol = rel_tol if periodic else 0.05
        for gi, (p, nn, a, r) in enumerate(reps):
            if p == periodic and nn == n and abs(amp[i] - a) <= tol * max(a, 1e-300) \
                    and abs(rms[i] - r) <= tol * max(r, 1e-300):
                groups[gi].append(i)
                break
        else:
            reps.append((periodic, n, amp[i], rms[i]))
            groups.append([i])
    order = sorted(range(len(groups)), key=lambda g: -len(groups[g]))
    groups = [groups[g] for g in order]
    for gi, g in enumerate(groups):
        label[g] = gi
    return label, groups


def bifurcation_diagram(system, forcing, omegas, *, progress=False, **options):
    """Stroboscopic bifurcation diagram: [`attractors`][absorber_jax.attractors] at every ``ω`` in
    ``omegas`` (same initial states and window resolution at each, the one the lowest frequency
    needs: one compilation).  Returns the list of [`AttractorMap`][absorber_jax.AttractorMap]s;
    plot with [`absorber_jax.plot_bifurcation_diagram`][absorber_jax.plot_bifurcation_diagram]."""
    from tqdm.auto import tqdm

    check_system_and_forcing(system, forcing, "bifurcation_diagram")
    om = np.asarray(omegas, dtype=float)
    if om.ndim != 1 or om.size < 1 or not np.all(np.isfinite(om)) or np.any(om <= 0):
        raise ValueError(f"omegas must be a 1-D array of frequencies > 0 [rad/s], got {omegas!r}")
    if options.get("initial_states") is None:
        options["initial_states"] = _sample_states(
            system, forcing, options.pop("samples", 32), float(options.pop("spread", 3.0)),
            options.pop("seed", 0))
    if options.get("resolution") is None:
        options["resolution"] = samples_per_period(system, float(om.min()))
    out = []
    for w in tqdm(om, desc="attractors", disable=not progress):
        out.append(attractors(system, forcing.with_omega(float(w)), **options))
    return out
