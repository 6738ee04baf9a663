"""The exact peak of a steady-state response over a frequency band, and its gradient.

``A(ω; θ)`` is the observable's half peak-to-peak amplitude on the period-1 orbit at ``ω``
(design parameters ``θ``); the band's peak is ``P(θ) = max_{ω ∈ band} A(ω; θ)``.

1. **Grid.** One vmapped shooting pass over ``n_freq`` frequencies finds the candidates: the
   ``peaks`` highest local maxima of the sampled curve (band edges included), ordered by
   frequency.  When the curve has fewer local maxima, the remaining slots hold the largest
   other grid values (still lower bounds of ``P``, so a minimax design may use them as
   constraints).
2. **Locate.** For each local maximum the slope ``dA/dω`` (forward mode through the implicit
   orbit: no finite differences) is bracketed between the grid neighbours and its zero is
   found by Illinois regula falsi (M. Dowell, P. Jarratt, *BIT* 11 (1971) 168), each trial
   orbit warm-started from the bracket end nearest to it.  A maximum at a band edge with the
   slope pointing out of the band stays there.
3. **Refined amplitude.** The extremes of the observable over the period are located between
   the samples by quintic Hermite interpolation of the observable and its first two time
   derivatives (from the vector field along the orbit).  ``A`` is then smooth in ``ω`` and
   ``θ`` (errors ~1e-12 of the amplitude on smooth orbits) instead of carrying the ~1e-7
   steps of parabolic interpolation, which would spoil the slope and its zero.
4. **Gradient** by the envelope theorem (P. Milgrom, I. Segal, *Econometrica* 70 (2002)
   583): at an interior maximum ``∂A/∂ω = 0``, so
   ``dP/dθ = ∂A/∂θ (ω*, θ)``, the amplitude differentiated at the fixed located frequency.
   No derivative of ``ω*`` is needed, and no frequency grid limits the value.

A peak whose slope does not change sign between the grid neighbours (a fold, where the
response jumps, or a peak narrower than the grid spacing) keeps its grid value and is flagged
``located = False``.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.checks import check_scalar, require_x64
from .._core.legacy import no_more
from .._core.status import Status
from .._integration.flow import state_scale
from .._integration.settings import integrator_from
from .._periodic.orbit import sample_orbit
from .._periodic.steady import check_system_and_forcing, make_config, solve_point
from .._systems.forcing import Harmonic, at_frequency, sweep_shape
from .._systems.params import get_param, replace_params
from .base import (
    Reparam,
    check_design,
    closed_form,
    design_method,
    legacy_objective,
    linear_amplitude,
    shooting_for_design,
)
from .objectives import ExactPeak

# kinds of a peak slot
LOCATED, EDGE, FILLER, UNBRACKETED = 0, 1, 2, 3
KIND_NAMES = {LOCATED: "located", EDGE: "band edge", FILLER: "grid point",
              UNBRACKETED: "not bracketed"}

# quintic Hermite on [0, 1]: coefficients a3..a5 from the end conditions (see _hermite_max)
_H = np.linalg.inv(np.array([[1.0, 1.0, 1.0], [3.0, 4.0, 5.0], [6.0, 12.0, 20.0]]))


def _hermite_max(y0, d0, c0, y1, d1, c1, h):
    """Largest value on ``[0, h]`` of the quintic matching value, first and second
    derivative at both ends (its slope has a zero there: ``d0 >= 0 >= d1``)."""
    D0, C0, D1, C1 = d0 * h, c0 * h * h, d1 * h, c1 * h * h
    a0, a1, a2 = y0, D0, 0.5 * C0
    rhs = jnp.stack([y1 - a0 - a1 - a2, D1 - a1 - 2 * a2, C1 - 2 * a2])
    a3, a4, a5 = jnp.asarray(_H) @ rhs
    dp = lambda s: a1 + 2 * a2 * s + 3 * a3 * s**2 + 4 * a4 * s**3 + 5 * a5 * s**4  # noqa: E731
    ddp = lambda s: 2 * a2 + 6 * a3 * s + 12 * a4 * s**2 + 20 * a5 * s**3  # noqa: E731
    # start from the zero of the slope's chord, then Newton (safeguarded to the interval)
    s = jnp.clip(D0 / jnp.where(D0 - D1 == 0, 1.0, D0 - D1), 0.0, 1.0)
    for _ in range(6):
        step = dp(s) / jnp.where(ddp(s) < 0, ddp(s), -1.0)
        s = jnp.clip(s - step, 0.0, 1.0)
    p = a0 + s * (a1 + s * (a2 + s * (a3 + s * (a4 + s * a5))))
    return jnp.maximum(p, jnp.maximum(y0, y1))


def _extreme(y, d, c, h):
    """Maximum of the periodic signal sampled at spacing ``h`` (values ``y``, first and second
    time derivatives ``d``, ``c``), located between samples."""
    n = y.shape[0]
    i = jnp.argmax(y)
    j = jnp.where(d[i] >= 0, i, (i - 1) % n)          # the interval [j, j+1] holds the maximum
    k = (j + 1) % n
    return _hermite_max(y[j], d[j], c[j], y[k], d[k], c[k], h)


def refined_amplitude(system, forcing, x, cfg, n=1):
    """Half peak-to-peak of ``system.observable`` over the period-``n`` orbit from the scaled
    state ``x``, its extremes located between samples (module docstring, step 3)."""
    s, ts, status = sample_orbit(system, forcing, x, n, cfg, n)

    def derivatives(t, si):
        def rate_of_obs(t_, s_):
            return jax.jvp(system.observable, (s_,), (system.vector_field(t_, s_, forcing),))

        f = system.vector_field(t, si, forcing)
        (y, d), (_, c) = jax.jvp(rate_of_obs, (t, si), (jnp.ones_like(t), f))
        return y, d, c

    y, d, c = jax.vmap(derivatives)(ts, s)
    h = ts[1] - ts[0]
    amp = 0.5 * (_extreme(y, d, c, h) + _extreme(-y, -d, -c, h))
    return amp, status


def amplitude_at(system, omega, amplitude, guess, cfg, method):
    """Refined amplitude at ``omega`` on the orbit found from ``guess`` (internal state; NaN:
    the method's start), the internal orbit state and the status.  A ``linear`` system's
    under a single exact harmonic comes from its closed-form response
    (``linear_amplitude``; ``guess``, ``cfg`` and the method unused)."""
    forcing = at_frequency(amplitude, omega)
    if closed_form(system, forcing):
        return linear_amplitude(system, forcing)
    res = solve_point(system, forcing, method, cfg, guess=guess, with_floquet=False)
    x_int = system.to_internal(res.state)
    a, st = refined_amplitude(system, forcing, x_int / state_scale(system, forcing), cfg)
    status = jnp.where(res.status == Status.SUCCESS, st, res.status)
    return a, (x_int, status)


def evaluate(system_at, v, omega, amplitude, guess, cfg, method):
    """``(A, [dA/dω, dA/dv...], internal state, status)`` at ``omega`` for the design ``v``
    (``system_at(v)`` is the system): one forward-mode pass whose first tangent is the
    slope that locates the peak and whose others are the design gradient there."""
    def f(z):
        a, aux = amplitude_at(system_at(z[1:]), z[0], amplitude, guess, cfg, method)
        return a, (a, aux)

    z = jnp.concatenate([jnp.reshape(omega, (1,)), jnp.asarray(v, dtype=float)])
    grad, (a, (x, st)) = jax.jacfwd(f, has_aux=True)(z)
    ok = (st == Status.SUCCESS) & jnp.all(jnp.isfinite(grad)) & jnp.isfinite(a)
    st = jnp.where(ok | (st != Status.SUCCESS), st, Status.NONFINITE)
    return a, jnp.where(ok, grad, 0.0), x, st


def candidates(omegas, amps, slopes, ok, peaks):
    """The ``peaks`` slots (module docstring, step 1), ordered by frequency: for each, its kind
    (LOCATED: a bracket ``[ω_j, ω_j+1]`` where the slope turns from + to -; EDGE: a band edge
    whose slope points out of the band; FILLER: a grid point) and grid index ``j``."""
    F = omegas.shape[0]
    a = jnp.where(ok, amps, -jnp.inf)
    big = 1e3 * (jnp.max(jnp.where(ok, jnp.abs(amps), 0.0)) + 1.0)
    bracket = ok[:-1] & ok[1:] & (slopes[:-1] > 0) & (slopes[1:] <= 0)
    # a bracket's height estimated by the cubic through the values and slopes at its ends:
    # a narrow peak between two low grid points still ranks by its own height
    s_ = jnp.linspace(0.0, 1.0, 17)[:, None]
    h = jnp.diff(omegas)
    y0, y1 = jnp.where(ok, amps, 0.0)[:-1], jnp.where(ok, amps, 0.0)[1:]
    d0, d1 = slopes[:-1] * h, slopes[1:] * h
    cubic = ((2 * s_**3 - 3 * s_**2 + 1) * y0 + (s_**3 - 2 * s_**2 + s_) * d0
             + (-2 * s_**3 + 3 * s_**2) * y1 + (s_**3 - s_**2) * d1)
    height = jnp.maximum(jnp.max(cubic, axis=0), jnp.maximum(y0, y1))
    s_br = jnp.where(bracket, height + big, -jnp.inf)
    s_lo = jnp.where(ok[0] & (slopes[0] <= 0), a[0] + big, -jnp.inf)
    s_hi = jnp.where(ok[-1] & (slopes[-1] >= 0), a[-1] + big, -jnp.inf)
    # a grid point already taken as a band-edge peak is no filler
    fill = a.at[0].set(jnp.where(jnp.isfinite(s_lo), -jnp.inf, a[0]))
    fill = fill.at[-1].set(jnp.where(jnp.isfinite(s_hi), -jnp.inf, a[-1]))
    score = jnp.concatenate([s_br, jnp.stack([s_lo, s_hi]), fill])
    kinds = jnp.concatenate([jnp.full(F - 1, LOCATED), jnp.array([EDGE, EDGE]),
                             jnp.full(F, FILLER)])
    index = jnp.concatenate([jnp.arange(F - 1), jnp.array([0, F - 1]), jnp.arange(F)])
    _, top = jax.lax.top_k(score, peaks)
    kind, j = kinds[top], index[top]
    where = jnp.where(kind == LOCATED, 0.5 * (omegas[j] + omegas[jnp.minimum(j + 1, F - 1)]),
                      omegas[j])
    order = jnp.argsort(where)
    return kind[order], j[order]


def _illinois_point(a, b, ga, gb):
    """The regula falsi point of the brackets ``[a, b]`` (slopes ``ga > 0 >= gb``), kept
    1e-3 of the bracket inside it."""
    w = (a * gb - b * ga) / np.where(gb - ga == 0, 1.0, gb - ga)
    span = b - a
    return np.clip(w, a + 1e-3 * span, b - 1e-3 * span)


def locate(evaluate_slots, omegas, grid, kind, j, xtol, max_iter):
    """The slots: the zero of the slope in each bracket ``[ω_j, ω_j+1]`` by Illinois regula
    falsi (LOCATED), or the grid point ``j`` as it is.  ``grid``: the grid pass by frequency
    (numpy); ``evaluate_slots(w, guesses)``: one compiled evaluation of every slot.  Returns
    ``(ω, A, gradient, state, status, iterations)`` per slot.  A slot stops once its step or
    bracket is below ``xtol * ω``, its orbit failed or its slope is 0; the loop runs while
    any slot goes on (slots that stopped are evaluated again with the others and their
    results discarded: one program of fixed shape)."""
    amps, grads, states, status = grid
    F = omegas.shape[0]
    k = np.minimum(j + 1, F - 1)
    a, b, ga, gb = omegas[j].copy(), omegas[k].copy(), grads[j, 0].copy(), grads[k, 0].copy()
    xa, xb = states[j].copy(), states[k].copy()
    start = np.where((kind == LOCATED) & (amps[k] > amps[j]), k, j)
    w, amp, grad = omegas[start].copy(), amps[start].copy(), grads[start].copy()
    x, st = states[start].copy(), status[start].copy()
    side, it = np.zeros(len(j), int), np.zeros(len(j), int)
    done = kind != LOCATED
    while np.any(~done & (it < max_iter)):
        active = ~done & (it < max_iter)
        wn = np.where(active, _illinois_point(a, b, ga, gb), w)
        guess = np.where((wn - a < b - wn)[:, None], xa, xb)
        amp_n, grad_n, x_n, st_n = evaluate_slots(wn, guess)
        g = grad_n[:, 0]
        left = g < 0                        # the zero lies in [a, w]: w replaces b

        def upd(new, old, active=active):
            return np.where(active.reshape((-1,) + (1,) * (old.ndim - 1)), new, old)

        a_new, b_new = np.where(left, a, wn), np.where(left, wn, b)
        stop = ((st_n != Status.SUCCESS) | (np.abs(wn - w) <= xtol * wn)
                | (b_new - a_new <= xtol * wn) | (g == 0))
        xa = upd(np.where(left[:, None], xa, x_n), xa)
        xb = upd(np.where(left[:, None], x_n, xb), xb)
        ga = upd(np.where(left, np.where(side == 1, 0.5 * ga, ga), g), ga)
        gb = upd(np.where(left, g, np.where(side == -1, 0.5 * gb, gb)), gb)
        a, b = upd(a_new, a), upd(b_new, b)
        side, it = upd(np.where(left, 1, -1), side), upd(it + 1, it)
        w, amp, grad, x, st = (upd(n, o) for n, o in ((wn, w), (amp_n, amp), (grad_n, grad),
                                                       (x_n, x), (st_n, st)))
        done = upd(stop, done)
    return w, amp, grad, x, st, it


class BandPeak(eqx.Module):
    """The exact peak of a response over a band ([`exact_peak`][absorber_jax.exact_peak]).

    Per slot (``peaks`` of them, ordered by frequency): ``omegas`` [rad/s], ``amplitudes``
    (the observable's half peak-to-peak amplitude, its extremes located between the orbit's
    samples by quintic Hermite interpolation, so smooth in ω and the parameters), ``kinds``
    (0 located: the zero of ``dA/dω`` found; 1 band edge; 2 grid point; 3 not bracketed),
    ``located``, ``iterations`` (steps of the Illinois variant of regula falsi: M. Dowell,
    P. Jarratt, *BIT* 11 (1971) 168), ``status``; ``gradients``: ``d amplitude / d
    parameter`` per slot and named parameter, by the envelope theorem (at a located peak
    ``∂A/∂ω = 0``, so the amplitude is differentiated at the fixed located frequency:
    P. Milgrom, I. Segal, *Econometrica* 70 (2002) 583).
    ``grid_omegas``/``grid_amplitude``/``grid_status``: the coarse pass (the uniform grid,
    then the modal points)."""

    omegas: np.ndarray
    amplitudes: np.ndarray
    kinds: np.ndarray
    iterations: np.ndarray
    status: np.ndarray
    gradients: dict
    grid_omegas: np.ndarray
    grid_amplitude: np.ndarray
    grid_status: np.ndarray

    @property
    def located(self):
        """Per slot: whether the peak was located (the zero of ``dA/dω`` found)."""
        return self.kinds == LOCATED

    @property
    def ok(self):
        """Per slot: whether its orbit solves succeeded (``status == Status.SUCCESS``)."""
        return self.status == Status.SUCCESS

    @property
    def index(self):
        """Slot of the band's peak (the largest amplitude among successful slots)."""
        return int(np.argmax(np.where(self.ok, self.amplitudes, -np.inf)))

    @property
    def value(self):
        """The band's peak amplitude."""
        return float(self.amplitudes[self.index]) if self.ok.any() else float("nan")

    @property
    def omega(self):
        """The frequency of the band's peak [rad/s]."""
        return float(self.omegas[self.index]) if self.ok.any() else float("nan")

    @property
    def gradient(self):
        """``d value / d parameter`` (the peak slot's row of ``gradients``)."""
        return {k: float(v[self.index]) for k, v in self.gradients.items()}

    def summary(self):
        """A printable text: the band's peak and, per slot, its frequency, amplitude, kind,
        iterations and status."""
        lines = []
        for j in range(len(self.omegas)):
            lines.append(f"  ω = {self.omegas[j]:.8g} rad/s  amplitude {self.amplitudes[j]:.8g}"
                         f"  ({KIND_NAMES[int(self.kinds[j])]}, {int(self.iterations[j])} "
                         f"iterations, status {int(self.status[j])})")
        return f"peak {self.value:.8g} at ω = {self.omega:.8g} rad/s\n" + "\n".join(lines)


def modal_seeds(system, lo, hi):
    """Grid points at the linearisation's lightly damped modes: for each of the ``S // 2``
    eigenvalues ``λ = -ζω + iω_d`` of the vector field's Jacobian at rest (no forcing) with
    the largest imaginary parts, ``ω_d (1 - ζ)``, ``ω_d`` and ``ω_d (1 + ζ)`` (the
    half-power band), clipped to ``[lo, hi]``.  A resonance narrower than the grid spacing
    (a lightly damped mode that a design has detuned or left undamped) is then bracketed
    whatever the grid.  Overdamped modes and a non-finite Jacobian give band-edge points."""
    rest = system.rest_state()
    still = Harmonic(amplitude=0.0, omega=1.0)
    J = jax.jacfwd(lambda s: system.vector_field(jnp.zeros(()), s, still))(rest)
    finite = jnp.all(jnp.isfinite(J))
    lam = jnp.linalg.eigvals(jnp.where(finite, J, 0.0))
    lam = lam[jax.lax.top_k(jnp.imag(lam), system.num_states // 2)[1]]
    wd = jnp.abs(jnp.imag(lam))
    zeta = jnp.clip(-jnp.real(lam) / jnp.maximum(jnp.abs(lam), 1e-300), 0.0, 1.0)
    w = jnp.concatenate([wd * (1 - zeta), wd, wd * (1 + zeta)])
    w = jnp.where(finite & jnp.isfinite(w), w, lo)
    return jax.lax.stop_gradient(jnp.clip(w, lo, hi))


def design_system(system, names, reparam, u):
    """``system`` with the named parameters at ``reparam.forward(u)``."""

    return replace_params(system, dict(zip(names, reparam.forward(u))), check=False)


@eqx.filter_jit
def evaluate_batch(system, names, reparam, u, omegas, amplitude, guesses, cfg, tol,
                   newton_steps):
    """``evaluate`` at each of ``omegas`` from its guess (vmapped, design shooting with
    ``tol`` and ``newton_steps``) for the design ``u``: per frequency ``(A, [dA/dω,
    dA/du...], internal state, status)``.  Compiled once per batch size: ``peak_core``'s
    grid pass and its Illinois iterations share it."""
    method = shooting_for_design(tol, newton_steps)

    def system_at(v):
        return design_system(system, names, reparam, v)

    return jax.vmap(lambda w, g: evaluate(system_at, u, w, amplitude, g, cfg, method))(
        omegas, guesses)


def evaluate_points(system, names, reparam, u, omegas, amplitude, guesses, cfg, tol,
                    newton_steps, batch):
    """``evaluate_batch`` over any number of frequencies, ``batch`` at a time (the last
    call padded with its last point), so that every call runs the same compiled program;
    numpy outputs."""
    omegas = np.asarray(omegas, dtype=float)
    guesses = np.asarray(guesses, dtype=float)
    n = omegas.shape[0]
    pad = (-n) % batch
    w = np.concatenate([omegas, np.repeat(omegas[-1:], pad)])
    g = np.concatenate([guesses, np.repeat(guesses[-1:], pad, axis=0)])
    parts = [[np.asarray(v) for v in evaluate_batch(
        system, names, reparam, u, jnp.asarray(w[i:i + batch]), amplitude,
        jnp.asarray(g[i:i + batch]), cfg, tol, newton_steps)] for i in range(0, n + pad, batch)]
    return tuple(np.concatenate([p[m] for p in parts])[:n] for m in range(4))


@eqx.filter_jit
def _modal_seeds_at(system, names, reparam, u, lo, hi):
    return modal_seeds(design_system(system, names, reparam, u), lo, hi)


def peak_core(system, names, reparam, u, omegas, amplitude, guesses, cfg, tol, newton_steps,
              peaks, xtol, max_iter, modes=True):
    """Slots of the band's peak at the design ``u`` (``reparam.forward(u)`` gives the named
    parameters; ``Reparam.plain``: ``u`` are the parameters themselves): the grid pass (the
    ``omegas`` and, with ``modes``, the ``modal_seeds``), the located frequencies, the
    refined amplitudes and their gradients in ``u`` at the located frequencies (envelope
    theorem).  ``guesses``: warm starts on ``omegas`` (the seeds start from the method's
    guess).  The ``grid_*`` outputs list ``omegas`` first, then the seeds (numpy arrays).

    One compiled program of ``peaks`` lanes (``evaluate_batch``) serves both the grid,
    evaluated ``peaks`` frequencies at a time, and every Illinois iteration (all slots at
    once): compiled as two programs (the grid's batch and the slots') inside one
    ``jax.jit``, the hardening oscillator of tests/design/test_peak.py took 55 s to compile, one
    program alone 21 s; runs are milliseconds there."""
    omegas = np.asarray(omegas, dtype=float)
    guesses = np.asarray(guesses, dtype=float)
    grid_w, grid_g = omegas, guesses
    if modes:
        seeds = np.asarray(_modal_seeds_at(system, names, reparam, u, jnp.asarray(omegas[0]),
                                           jnp.asarray(omegas[-1])))
        grid_w = np.concatenate([omegas, seeds])
        grid_g = np.concatenate([guesses, np.full((seeds.shape[0], guesses.shape[1]),
                                                  np.nan)])

    def evaluate_slots(w, g):
        return evaluate_points(system, names, reparam, u, w, amplitude, g, cfg, tol,
                               newton_steps, peaks)

    grid = evaluate_slots(grid_w, grid_g)
    amps, grads, states, status = grid
    order = np.argsort(grid_w, kind="stable")
    w_sorted = grid_w[order]
    by_freq = tuple(v[order] for v in grid)
    kind, j = (np.asarray(v) for v in candidates(
        jnp.asarray(w_sorted), jnp.asarray(by_freq[0]), jnp.asarray(by_freq[1][:, 0]),
        jnp.asarray(by_freq[3] == Status.SUCCESS), peaks))
    w, a, g, x, st, it = locate(evaluate_slots, w_sorted, by_freq, kind, j, xtol, max_iter)
    return dict(omegas=w, amplitudes=a, kinds=kind, iterations=it, status=st, jac=g[:, 1:],
                slopes=g[:, 0], states=x, grid_omegas=grid_w, grid_amplitude=amps,
                grid_states=states, grid_status=status, grid_jac=grads[:, 1:])


def exact_peak(system, band, *, amplitude, params=(), objective=None, method=None,
               integrator=None, **legacy) -> BandPeak:
    """The largest steady-state amplitude of ``system.observable`` over ``band = (lo, hi)``
    [rad/s] under a harmonic force of amplitude ``amplitude`` F0 [N] (or a periodic forcing
    given as ``amplitude``, swept through its ``with_omega(ω)``), located exactly, with its
    gradient in the named ``params`` by the envelope theorem (``BandPeak``).

    - ``objective``: an ``objectives.ExactPeak`` carrying the grid and the location options
      (``n_freq`` points of the coarse grid that brackets the peaks, ``peaks`` slots, ``modes``:
      grid points at the lightly damped modes and their half-power points, ``xtol``,
      ``max_iter``); default ``ExactPeak()``.
    - ``method``: the ``Shooting`` of each orbit, default ``Shooting(tol=1e-8,
      newton_steps=40)``; ``integrator``: default the design tolerances (1e-10).

    A ``linear`` system (a ``StructuralSystem`` of linear elements) under a harmonic force
    is not integrated: its amplitudes come from its closed-form response
    (``harmonic_response``), and ``method`` and ``integrator`` are unused.

    ```python
    import absorber_jax as aj
    system, _ = aj.presets.impact("kelvin_voigt")
    pk = aj.exact_peak(system, (25.0, 45.0), amplitude=2.0, params=["k1", "c1"])
    pk.value, pk.omega, pk.gradient
    ```
    """
    obj = ExactPeak() if objective is None else objective
    if not isinstance(obj, ExactPeak):
        raise ValueError(f"exact_peak.objective must be an aj.objectives.ExactPeak(...), got "
                         f"{type(obj).__name__}")
    obj = legacy_objective(obj, "exact_peak", legacy)
    method = design_method(method, "exact_peak", legacy, default_tol=1e-8)
    integ = integrator_from(integrator, "design", "exact_peak", legacy,
                            fields=("solver", "rtol", "atol", "max_steps"))
    no_more("exact_peak", legacy)
    return exact_peak_of(system, band, amplitude=amplitude, params=params, n_freq=obj.n_freq,
                         peaks=obj.peaks, tol=method.tol, rtol=integ.rtol, atol=integ.atol,
                         newton_steps=method.newton_steps, solver=integ.solver,
                         xtol=obj.xtol, max_iter=obj.max_iter, modes=obj.modes,
                         max_steps=integ.max_steps)


def exact_peak_of(system, band, *, amplitude, params, n_freq, peaks, tol, rtol, atol,
                  newton_steps, solver, xtol, max_iter, modes, max_steps=200_000) -> BandPeak:
    """``exact_peak`` with its options unpacked."""

    require_x64("exact_peak")
    amplitude = sweep_shape(amplitude, "exact_peak")
    check_system_and_forcing(system, at_frequency(amplitude, 1.0), "exact_peak")
    lo, hi = band
    check_scalar("exact_peak", "band[0]", lo, lo=0.0, lo_open=True)
    check_scalar("exact_peak", "band[1]", hi, lo=float(lo), lo_open=True)
    if not isinstance(n_freq, int) or n_freq < 3:
        raise ValueError(f"exact_peak.n_freq must be an integer >= 3, got {n_freq!r}")
    if not isinstance(peaks, int) or not 1 <= peaks <= n_freq:
        raise ValueError(f"exact_peak.peaks must be an integer in [1, n_freq], got {peaks!r}")
    check_scalar("exact_peak", "xtol", xtol, lo=0.0, lo_open=True)
    omegas = np.linspace(float(lo), float(hi), n_freq)
    names = tuple(params)
    if names:
        names, _ = check_design(system, names, omegas, "peak")
    p0 = jnp.array([float(get_param(system, k)) for k in names])
    cfg = make_config(system, at_frequency(amplitude, float(omegas[0])), solver, rtol, atol,
                      max_steps)
    guesses = jnp.full((n_freq, system.num_states), jnp.nan, dtype=jnp.float64)
    out = peak_core(system, names, Reparam.plain(len(names)), p0, jnp.asarray(omegas),
                    amplitude, guesses, cfg, float(tol), int(newton_steps),
                    int(peaks), float(xtol), int(max_iter), bool(modes))
    out = {k: np.asarray(v) for k, v in out.items()}
    return BandPeak(omegas=out["omegas"], amplitudes=out["amplitudes"], kinds=out["kinds"],
                    iterations=out["iterations"], status=out["status"],
                    gradients={k: out["jac"][:, i] for i, k in enumerate(names)},
                    grid_omegas=out["grid_omegas"], grid_amplitude=out["grid_amplitude"],
                    grid_status=out["grid_status"])
