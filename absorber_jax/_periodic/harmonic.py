r"""Harmonic balance: periodic orbits as truncated Fourier series, the equations of motion
balanced harmonic by harmonic.

The orbit of period ``T = 2π/ω`` is sought as

$$x(t) = c_0 + \sum_{k=1}^{H} \big(a_k \cos k\omega t + b_k \sin k\omega t\big),$$

``x`` the system's internal state (first-order form, ``ẋ = f(t, x)``) scaled by its state
scale.  The residual is the Galerkin projection of ``ẋ - f(t, x)`` on the same harmonics,
evaluated by the alternating frequency–time scheme (T. M. Cameron, J. H. Griffin, *An
alternating frequency/time domain method for calculating the steady-state response of
nonlinear dynamic systems*, J. Appl. Mech. 56 (1989) 149): the series sampled at ``N``
uniform times, the vector field evaluated there (any law, smooth or not), projected back by
the discrete Fourier transform, exact for trigonometric polynomials of degree below ``N/2``.
Newton's Jacobian is the forward-mode derivative of that residual (``jax.jacfwd``), its
steps minimum-norm least squares for small balances (families of orbits, such as a floating
absorber's position, make it singular) and LU solves for large ones (``newton_solve``).

**Stability.**  By default (``stability="monodromy"``) the multipliers are the eigenvalues
of the full system's monodromy matrix over one period from the balanced orbit's state at
``t = 0``: a check by the shooting layer.  **Hill's method** (``stability="hill"``): a
perturbation ``e^{λt} p(t)``, ``p`` of period ``T``
expanded on the same harmonics, solves the linearised equation where ``λ`` is an eigenvalue
of ``-ω ∂R/∂c`` (``R`` the residual with time scaled by ``1/ω``, ``c`` the coefficients).
Of its ``n(2H+1)`` eigenvalues (each Floquet exponent repeated at ``λ + ikω``, its
eigenvector shifted by ``k`` harmonics), the ``n`` whose eigenvectors are centred on
harmonic zero are kept (sorting by symmetry: A. Lazarus, O. Thomas, *A harmonic-based
method for computing the stability of periodic solutions of dynamical systems*, C. R.
Mécanique 338 (2010) 510); the multipliers are ``exp(λT)``.  The constant harmonic alone is
no criterion: the Floquet modes of a symmetric orbit (a Duffing oscillator's) have none.
Truncation shifts the multipliers: for smooth laws they converge to the monodromy's as
``H`` grows; on a law with a kink the eigenfunctions carry slowly decaying harmonics and
they may not (see ``HarmonicBalance.stability``).

**Accuracy.**  For smooth laws the error falls exponentially with ``H`` (a Duffing
oscillator's amplitude: 8.6e-3 at ``H = 1``, 2.6e-9 at ``H = 9`` against shooting); for laws
with a kink or a jump (a clearance, dry friction) algebraically (a Kelvin–Voigt clearance
contact: about ``H^-1.3``, 4e-6 at ``H = 128``).  The exact event-driven laws
(rigid impacts, exact stick–slip) have no vector field to balance and are refused.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from .._core.checks import check_scalar
from .._core.status import Status
from .._integration.flow import integrate_flow, state_scale
from .._systems.base import is_hybrid
from .base import AbstractSinglePassMethod
from .orbit import SAMPLES_PER_PERIOD, floquet, sample_statistics, steady_of

# the first guess is projected from the last of this many periods integrated from the start
WARMUP = 4
# fractions of the Newton step tried, the one with the least residual taken
STEP_FRACTIONS = (1.0, 0.5, 0.25, 0.1)
# Newton steps of balances with up to this many unknowns by SVD (minimum norm), beyond by LU
SVD_SIZE = 40


class HarmonicBalance(AbstractSinglePassMethod):
    """Harmonic balance with the alternating frequency–time scheme, its orbits' stability
    from the monodromy or by Hill's method (see the module above): a steady-state method
    for ``steady_state`` and ``frequency_response`` (vmapped over frequencies like
    shooting).

    **Arguments**

    - ``harmonics``: the number ``H`` of harmonics kept (the series has ``2H + 1`` terms per
      state).
    - ``samples``: time samples per period of the frequency–time scheme (``None``:
      ``max(64, 8H)``; at least ``2H + 1``).  More samples resolve a law's kinks better
      without adding unknowns.
    - ``tol``: Newton's tolerance on the largest residual coefficient, the state scaled to
      order one and time by ``1/ω``.
    - ``newton_steps``: Newton iteration budget.
    - ``condense``: where the system separates into a linear structure and force laws at a
      few degrees of freedom (``system.condensation()``: a ``StructuralSystem`` whose
      elements have no states of their own), the unknowns are the harmonics of those
      degrees of freedom only, the structure entering through its exact receptance at each
      harmonic.  ``False``: balance the whole state.
    - ``stability``: how the Floquet multipliers are found.  ``"monodromy"`` (default): the
      eigenvalues of the monodromy matrix of the full system over one period from the
      orbit's state at ``t = 0`` (one integration with its tangents: a check by the
      shooting layer, right wherever the orbit is).  ``"hill"``: Hill's method on the
      balance's Jacobian (no integration; full balance only), accurate for smooth laws, but
      not on a law with a kink: on NLvib example 03's unilateral spring at Ω = 0.7357, a
      stable orbit whose multipliers are 0.94, 0.73 and a complex pair of modulus 0.82,
      Hill's method gives moduli 2.28 and 0.37 at H = 21, a pair of 0.31 at H = 42 and a
      pair of 1.35 at H = 84 in place of 0.94 and 0.73, and the labels with them.

    The first guess of the full balance is the method's own start (the system's linear
    response) or the state a caller gives, integrated over ``WARMUP`` periods, the last
    projected on the harmonics; that of the condensed balance is the structure's response
    without its elements' forces, in the frequency domain (no integration, so no step set
    by the structure's stiffest mode);
    Newton's steps are damped (the fraction of ``STEP_FRACTIONS`` with the least residual).
    Smooth laws only: exact event-driven laws (``Restitution``, exact Coulomb or Stribeck)
    are refused.

    ```python
    ss = aj.steady_state(system, forcing, method=aj.HarmonicBalance(harmonics=15))
    ```
    """

    harmonics: int = eqx.field(static=True, default=10)
    samples: int | None = eqx.field(static=True, default=None)
    tol: float = eqx.field(static=True, default=1e-9)
    newton_steps: int = eqx.field(static=True, default=30)
    condense: bool = eqx.field(static=True, default=True)
    stability: str = eqx.field(static=True, default="monodromy")

    def __check_init__(self):
        if self.stability not in ("monodromy", "hill"):
            raise ValueError("HarmonicBalance.stability must be 'monodromy' or 'hill', got "
                             f"{self.stability!r}")
        if not isinstance(self.harmonics, int) or not 1 <= self.harmonics <= 512:
            raise ValueError("HarmonicBalance.harmonics must be an integer in [1, 512], got "
                             f"{self.harmonics!r}")
        if self.samples is not None and (not isinstance(self.samples, int)
                                         or self.samples < 2 * self.harmonics + 1):
            raise ValueError("HarmonicBalance.samples must be None or an integer >= 2 "
                             f"harmonics + 1 = {2 * self.harmonics + 1}, got {self.samples!r}")
        check_scalar("HarmonicBalance", "tol", self.tol, lo=0.0, lo_open=True)
        if not isinstance(self.newton_steps, int) or self.newton_steps < 1:
            raise ValueError("HarmonicBalance.newton_steps must be a positive integer, got "
                             f"{self.newton_steps!r}")

    @property
    def retry(self) -> bool:
        return False

    @property
    def time_samples(self) -> int:
        """Samples per period of the frequency–time scheme."""
        return self.samples if self.samples is not None else max(64, 8 * self.harmonics)

    def initial_state(self, system, forcing):
        return system.linear_guess(forcing)

    def solve(self, system, forcing, x0, cfg, *, with_floquet=True):
        if is_hybrid(system):
            raise ValueError(
                "HarmonicBalance needs a vector field to balance: the exact event-driven laws "
                "(Restitution, exact Coulomb or Stribeck) have none; use aj.Shooting(), or a "
                "compliant or smoothed law")
        condensation = system.condensation() if self.condense else None
        if condensation is not None and condensation.size:
            if self.stability == "hill":
                raise ValueError("HarmonicBalance(stability='hill') needs the full balance: "
                                 "give condense=False, or stability='monodromy'")
            return self._condensed(system, forcing, condensation, x0, cfg, with_floquet)
        H = self.harmonics
        scale = state_scale(system, forcing)

        def flat(v):
            return self.residual(system, forcing, v.reshape(2 * H + 1, -1), scale).reshape(-1)

        v, status, res, k = self._newton(flat, self.first_series(system, forcing, x0, cfg)
                                         .reshape(-1))
        c = v.reshape(2 * H + 1, -1)
        mult = (self.multipliers(system, forcing, c, lambda: jax.jacfwd(flat)(v), cfg)
                if with_floquet else None)
        return steady_from_series(system, forcing, c * scale, mult, status, res, k)

    def multipliers(self, system, forcing, c, jacobian, cfg):
        """The Floquet multipliers of the orbit whose scaled state has the coefficients
        ``c`` ``(2H+1, n)``, as ``stability`` asks: by Hill's method from ``jacobian()``
        (the balance's Jacobian with respect to ``c``, flattened), or from the monodromy at
        the orbit's scaled state at ``t = 0``."""
        if self.stability == "hill":
            return hill_multipliers(jacobian(), self.harmonics, forcing.omega, forcing.period)
        at_zero = fourier_matrices(self.harmonics, 1)[0][0] @ c
        return floquet(system, forcing, at_zero, 1, cfg)

    def residual(self, system, forcing, c, scale):
        """The balance's residual ``(2H+1, n)``: the Fourier coefficients of ``ẋ - f(t, x)``
        (time scaled by ``1/ω``) for the state whose coefficients are ``c`` times
        ``scale`` (the state scaled to order one), ``f`` sampled at ``samples`` instants a
        period (the alternating frequency–time scheme)."""
        H, N = self.harmonics, self.time_samples
        T, omega = forcing.period, forcing.omega
        E, P, D = fourier_matrices(H, N)
        ts = jnp.arange(N) * (T / N)
        f = jax.vmap(lambda t, y: system.vector_field(t, y * scale, forcing) / scale)(ts, E @ c)
        return D @ c - (P @ f) / omega

    def first_series(self, system, forcing, x0, cfg):
        """The first guess of a full balance ``(2H+1, n)`` (scaled state): the last of
        ``WARMUP`` periods integrated from scaled state ``x0``, projected on the harmonics."""
        _, P, _ = fourier_matrices(self.harmonics, self.time_samples)
        return P @ _warmed(system, forcing, x0, cfg, self.time_samples)

    def _newton(self, flat, v0):
        """Damped Newton on ``flat(v) = 0`` from ``v0``: ``(v, status, residual, steps)``.

        Differentiable (forward mode) by the implicit function theorem: the converged
        ``v*`` enters one more step with the last Jacobian held constant,
        ``v = v* - J⁺ R(v*)``, whose value is a chord step (``R(v*) ≈ 0``) and whose tangent
        with respect to anything ``flat`` closes over is ``-J⁺ ∂R/∂θ``: the derivative of
        the orbit, not of the iterations."""
        alphas = jnp.asarray(STEP_FRACTIONS)

        def body(c):
            v, _, _, k, _ = c
            J, r = jax.jacfwd(_with_value(flat), has_aux=True)(v)
            dv = newton_solve(J, -r)
            res = jnp.max(jnp.abs(r))
            # the fraction of the step that lowers the residual most
            trial = jax.vmap(lambda a: jnp.max(jnp.abs(flat(v + a * dv))))(alphas)
            trial = jnp.where(jnp.isfinite(trial), trial, jnp.inf)
            a = alphas[jnp.argmin(trial)]
            ok = jnp.all(jnp.isfinite(dv)) & jnp.isfinite(jnp.min(trial))
            return jnp.where(ok, v + a * dv, v), res, ok, k + 1, J

        def cond(c):
            _, res, ok, k, _ = c
            return ok & (res > self.tol) & (k < self.newton_steps)

        n = v0.shape[0]
        v, _, ok, k, J = jax.lax.while_loop(
            cond, body, (v0, jnp.asarray(jnp.inf), jnp.asarray(True), jnp.asarray(0),
                         jnp.zeros((n, n), v0.dtype)))
        v, J = jax.lax.stop_gradient(v), jax.lax.stop_gradient(J)
        step = newton_solve(J, -flat(v))
        v = jnp.where(jnp.all(jnp.isfinite(step)), v + step, v)
        res = jnp.max(jnp.abs(flat(v)))
        good = ok & (res <= self.tol) & jnp.all(jnp.isfinite(v))
        return v, jnp.where(good, Status.SUCCESS, Status.NO_CONVERGENCE), res, k

    def _condensed(self, system, forcing, cond, x0, cfg, with_floquet):
        """The orbit from the harmonics of the nonlinear degrees of freedom only (see
        ``condense``)."""
        H, N = self.harmonics, self.time_samples
        T, omega = forcing.period, forcing.omega
        scale = state_scale(system, forcing)
        E, P, D = fourier_matrices(H, N)
        ts = jnp.arange(N) * (T / N)
        omegas = omega * jnp.arange(H + 1)
        # each harmonic's coordinate responses to unit forces at u and to the load, and
        # what u sees of them: the receptances G (H+1, u, u) and the load's g (H+1, u)
        S = jax.vmap(cond.responses)(omegas)                # (H+1, n, u+1)
        u = cond.size
        seen = jax.vmap(cond.at_dofs)(S)
        G, g = seen[:, :, :u], seen[:, :, u]
        load = to_complex(P @ jax.vmap(forcing)(ts))        # (H+1,)
        # the length scale of the unknowns: the linear response's largest harmonic there
        length = jnp.maximum(jnp.max(jnp.abs(g * load[:, None])), 1e-300)

        def predicted(c):
            x, v = E @ c, E @ (omega * (D @ c))
            f = to_complex(P @ jax.vmap(cond.forces)(x, v))      # (H+1, u)
            return f, from_complex(jnp.einsum("kij,kj->ki", G, f) + g * load[:, None])

        def flat(y):
            c = y.reshape(2 * H + 1, u) * length
            return (c - predicted(c)[1]).reshape(-1) / length

        # first guess: the structure's response without its elements' forces (frequency
        # domain: no integration, whose step the structure's stiffest mode would set)
        y0 = from_complex(g * load[:, None]) / length
        y, status, res, k = self._newton(flat, y0.reshape(-1))
        c = y.reshape(2 * H + 1, u) * length
        f, _ = predicted(c)
        Q = jnp.einsum("kij,kj->ki", S[:, :, :u], f) + S[:, :, u] * load[:, None]
        Qc = from_complex(Q)                                  # (2H+1, n)
        states = jax.vmap(cond.to_state)(Qc, omega * (D @ Qc))   # the state's coefficients
        mult = (floquet(system, forcing, (E[0] @ states) / scale, 1, cfg) if with_floquet
                else None)
        return steady_from_series(system, forcing, states, mult, status, res, k)


def newton_solve(J, b):
    """A Newton step ``J⁻¹ b``: minimum-norm least squares (``lstsq``, by SVD) for systems of
    up to ``SVD_SIZE`` unknowns, so that a family of orbits (a singular ``J``) is stepped
    across by its least change; LU beyond, where XLA's SVD on the CPU costs hundreds of times
    more (121 unknowns: about 0.4 s against 1 ms), solved again with the diagonal shifted by
    ``1e-12 max|J|`` where the plain solve is singular.  The second solve depends on the
    first: two independent LU calls in one vmapped Newton loop deadlocked XLA's CPU runtime
    (32 frequencies at 121 unknowns, on two cores)."""
    if J.shape[0] <= SVD_SIZE:
        return jnp.linalg.lstsq(J, b)[0]
    x = jnp.linalg.solve(J, b)
    shift = jnp.where(jnp.all(jnp.isfinite(x)), 0.0, 1e-12 * jnp.max(jnp.abs(J)))
    return jnp.where(shift == 0.0, x, jnp.linalg.solve(J + shift * jnp.eye(J.shape[0]), b))


def _with_value(fn):
    """``fn`` returning its value twice: as output and as ``has_aux`` auxiliary (its value
    and Jacobian from one evaluation under ``jax.jacfwd``)."""
    def both(v):
        r = fn(v)
        return r, r

    return both


def steady_from_series(system, forcing, coefficients, mult, status, residual, iterations):
    """The ``SteadyState`` of the orbit whose internal state has the real Fourier
    ``coefficients`` ``(2H+1, states)``: its statistics from the series sampled as
    shooting's are (``SAMPLES_PER_PERIOD`` a period), ``mult`` its multipliers (None: not
    computed)."""
    H = (coefficients.shape[0] - 1) // 2
    Ns = SAMPLES_PER_PERIOD
    s = fourier_matrices(H, Ns)[0] @ coefficients
    if mult is None:
        mult = jnp.full((system.num_states,), jnp.nan + 0j)
    stats, stroke_max = sample_statistics(system, forcing, s,
                                          jnp.arange(Ns) * (forcing.period / Ns))
    return steady_of(system, stats, stroke_max, s[0], 1, mult, status, residual, iterations)


def _warmed(system, forcing, x0, cfg, N):
    """The first guess of a balance: the scaled states at ``N`` uniform instants of the last
    of ``WARMUP`` periods integrated from scaled state ``x0`` (transients partly decayed;
    non-finite values zeroed)."""
    T = forcing.period
    ts = (WARMUP - 1 + jnp.arange(N) / N) * T
    ys, _ = integrate_flow((system, forcing), x0, WARMUP * T, ts, cfg=cfg.over_periods(WARMUP))
    return jnp.where(jnp.isfinite(ys), ys, 0.0)


def to_complex(c):
    """Real Fourier coefficients ``(2H+1, …)`` (``c₀, a₁, b₁, …``) as complex amplitudes
    ``(H+1, …)`` of ``e^{ikωt}`` (``x = Re Σ X_k e^{ikωt}``: ``X₀ = c₀``, ``X_k = a_k - i b_k``)."""
    return jnp.concatenate([c[:1].astype(complex), c[1::2] - 1j * c[2::2]], axis=0)


def from_complex(X):
    """The inverse of ``to_complex``."""
    H = X.shape[0] - 1
    ab = jnp.stack([jnp.real(X[1:]), -jnp.imag(X[1:])], axis=1).reshape((2 * H,) + X.shape[1:])
    return jnp.concatenate([jnp.real(X[:1]), ab], axis=0)


def fourier_matrices(H, N):
    """The real Fourier basis of ``H`` harmonics at ``N`` uniform phases ``θ_j = 2πj/N``:
    ``E`` ``(N, 2H+1)`` (columns ``1, cos θ, sin θ, …, cos Hθ, sin Hθ``), its discrete
    projection ``P`` ``(2H+1, N)`` (``P E = I`` for ``N > 2H``) and the derivative ``D``
    with respect to ``θ`` on the coefficients."""
    theta = 2 * jnp.pi * jnp.arange(N) / N
    k = jnp.arange(1, H + 1)
    cos, sin = jnp.cos(theta[:, None] * k), jnp.sin(theta[:, None] * k)
    E = jnp.concatenate([jnp.ones((N, 1)), jnp.stack([cos, sin], axis=2).reshape(N, 2 * H)],
                        axis=1)
    P = jnp.concatenate([jnp.ones((1, N)) / N, 2.0 / N * E[:, 1:].T], axis=0)
    D = jnp.zeros((2 * H + 1, 2 * H + 1))
    # d/dθ (a_k cos kθ + b_k sin kθ) = k b_k cos kθ - k a_k sin kθ
    ia, ib = 1 + 2 * (k - 1), 2 + 2 * (k - 1)
    D = D.at[ia, ib].set(k.astype(float)).at[ib, ia].set(-k.astype(float))
    return E, P, D


def hill_multipliers(J, H, omega, T):
    """Floquet multipliers from the Jacobian ``J`` of the harmonic-balance residual (time
    scaled by ``1/ω``) by Hill's method: of the eigenvalues ``λ`` of ``-ω J``, the ``n``
    whose eigenvectors are centred on harmonic zero (their weight over the complex
    harmonics ``e^{ikωt}``, ``k = -H … H``, has its mean nearest zero: the copy
    ``λ + ikω`` of an exponent has it near ``-k``), mapped to ``exp(λT)``."""
    n = J.shape[0] // (2 * H + 1)
    lam, vec = jnp.linalg.eig(-omega * J)
    blocks = vec.reshape(2 * H + 1, n, -1)
    a, b = blocks[1::2], blocks[2::2]                  # cos and sin coefficients, k = 1 … H
    # the complex coefficients of e^{ikθ} and e^{-ikθ}: (a - ib)/2 and (a + ib)/2
    plus = jnp.sum(jnp.abs(a - 1j * b) ** 2, axis=1) / 4
    minus = jnp.sum(jnp.abs(a + 1j * b) ** 2, axis=1) / 4
    zero = jnp.sum(jnp.abs(blocks[0]) ** 2, axis=0)
    k = jnp.arange(1, H + 1)[:, None]
    total = zero + jnp.sum(plus + minus, axis=0)
    centre = jnp.sum(k * (plus - minus), axis=0) / total
    keep = jnp.argsort(jnp.abs(centre))[:n]
    return jnp.exp(lam[keep] * T)
