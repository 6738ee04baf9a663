r"""Closed-form flights: the segments of a hybrid integration whose modes are linear.

Between two events a rigid-impact system (linear structure, rigid walls, a harmonic load)
obeys a linear ODE with constant coefficients, forced by a sum of harmonics:

$$\dot x = A_m x + d_m + b_m F(t), \qquad
F(t) = \mathrm{Im}\sum_j c_j e^{i k_j \omega t}
     = \sum_j \big(\mathrm{Im}\,c_j \cos k_j\omega t + \mathrm{Re}\,c_j \sin k_j\omega t\big),$$

``A_m``, ``b_m``, ``d_m`` depending on the mode ``m`` only (free flight, or a body held
against its wall).  Adding ``1`` and the pairs ``(cos k_jωt, sin k_jωt)`` to the state makes
it autonomous, ``ż = Â z`` with

$$\hat A = \begin{pmatrix} A_m & d_m & b_m\,\mathrm{Im}\,c_1 & b_m\,\mathrm{Re}\,c_1 & \cdots\\
0 & 0 & & & \\ & & 0 & -k_1\omega & \\ & & k_1\omega & 0 & \\ & & & & \ddots \end{pmatrix},$$

so the flow over a time ``τ`` is the matrix exponential, ``z(t + τ) = e^{\hat A τ} z(t)``:
exact to rounding, whatever the tolerances (C. Moler, C. Van Loan, *Nineteen dubious ways
to compute the exponential of a matrix, twenty-five years later*, SIAM Review 45 (2003) 3).

**Nodes.**  The flight is evaluated on nodes ``h`` apart, ``h`` the hybrid integration's
step limit (``event_step_limit``, a 256th of the forcing period) or less, so that
``‖Â h‖∞ ≤ 1/4``: ``E = e^{Â h}`` is then its Taylor polynomial of degree
``TAYLOR_ORDER`` (remainder below ``1e-17``), and the ``NODES`` nodes of a window are
``I, E, E², …`` times its first node's state (one batched product).  The nodes lie on the
grid ``t0 + j h`` of the whole integration, so that save times on that grid are nodes; the
operators of the all-open mode are computed once per integration.  An event is the first
node where the switching function has crossed zero upwards; it is then located on the
exact flow between that node and the one before it (Newton steps kept inside the bracket
by bisection, to the rounding of the time).  Between two nodes below zero where the
switching function turns (its rate from positive to negative) and the cubic through the
two nodes' values and rates comes within ``APEX_MARGIN`` of zero, the turn itself is
located on the exact flow: a crossing there and back between two nodes (an excursion
through a wall near grazing) is an event, not missed.  Save times off the grid are reached
from the node before them, ``e^{Â δ}`` with ``δ < h``.

**Derivatives.**  The event times are located on values without tangents, and a segment
returns the state at the located time with its tangent at fixed time, which
``hybrid_solve`` turns into the saltation of the event (its module docstring).  With save
times (orbit statistics) forward-mode AD differentiates the windows themselves.  Without
(a period map: shooting's and continuation's Jacobians, Floquet multipliers) the windows
run on values and the segment carries a custom JVP (``_flight``): the JVP of ``e^{Âτ} z``
over the segment's duration ``τ``, by ``expm`` (its Fréchet derivative where the
parameters carry tangents).  The forcing frequency alone, where it enters ``Â`` only
through the oscillators' rotation block (``frequency_in_rotation_only``: continuation and
sweeps in ``omega``), is a direction of the windows' integration like the state, its
tangent from one exponential of ``2J`` more rows a segment (``_frequency_jvp``).  For a
period map's derivative in other parameters, ``flight_linearizations`` linearizes a
batch of recorded segments at once (the replay of ``stickslip.closed_form_jacobian``).

Systems declare such modes through ``AbstractHybridSystem.affine_modes``; the matrices
are taken from ``mode_rate`` by forward-mode AD with the forcing's value as an input.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from .._core.status import Status
from .._systems.forcing import AbstractForcing, AbstractPeriodicForcing

# Taylor degree of e^{Âh} with ‖Âh‖∞ <= NORM_BOUND: remainder <= 0.25^13/13! e^0.25 ~ 3e-18
TAYLOR_ORDER = 12
NORM_BOUND = 0.25
# squarings of the scaled exponential at most (norms up to 0.25 * 2^64)
MAX_SQUARINGS = 64
# nodes per window (one batched product of the powers I, E, ..., E^(NODES-1)); a window
# also ends at its NODES-th save time
NODES = 32
# event location: Newton steps bracketed by bisection, at most this many
LOCATE_ITERATIONS = 80
# an apex of a switching function between two nodes, estimated by the cubic through their
# values and rates (error ~ (ωh)⁴/384 ~ 1e-9 of its amplitude), is checked on the exact flow
# when it comes within this of zero
APEX_MARGIN = 1e-6
# times within this fraction of a node spacing of a node count as on it (rounding of the
# grid's times)
NODE_SLACK = 1e-6


class _ValueForcing(AbstractForcing):
    """A forcing whose value is ``value`` at every time (the rate's load as an input of
    ``mode_rate``, differentiated to get ``b``)."""

    value: object
    omega: object
    amplitude: object

    def __call__(self, t):
        return self.value


def mode_matrix(system, forcing, mode, scale, t):
    """``Â`` of ``mode`` on the scaled state: ``ż = Â z`` with
    ``z = (x, 1, cos k_jωt, sin k_jωt, …)`` (module docstring).  ``t``: any time [s] (the
    modes are time-invariant); no tangent."""
    orders = jnp.asarray(forcing.harmonics()[0], dtype=float)
    n = scale.shape[0]
    top = _mode_rows(system, forcing, mode, scale, t)
    J = orders.shape[0]
    blocks = _rotation(orders * forcing.omega, scale.dtype)
    lower = jnp.zeros((1 + 2 * J, n + 1 + 2 * J), scale.dtype)
    lower = lower.at[1:, n + 1:].set(blocks)
    return jnp.concatenate([top, lower], axis=0)


def _rotation(rates, dtype):
    """The oscillators' block of ``Â``: ``[[0, -r_j], [r_j, 0]]`` for each rate ``r_j``."""
    J = rates.shape[0]
    idx = jnp.arange(J)
    return (jnp.zeros((2 * J, 2 * J), dtype).at[2 * idx, 2 * idx + 1].set(-rates)
            .at[2 * idx + 1, 2 * idx].set(rates))


def _mode_rows(system, forcing, mode, scale, t):
    """The state's rows of ``mode_matrix``: ``(A, d, b Im c_1, b Re c_1, …)``."""
    _, c = forcing.harmonics()
    n = scale.shape[0]

    def rate(x, f):
        load = _ValueForcing(f, forcing.omega, forcing.amplitude)
        return system.mode_rate(t, x * scale, load, mode) / scale

    x0, f0 = jnp.zeros((n,), scale.dtype), jnp.zeros((), scale.dtype)
    d = rate(x0, f0)
    A, b = jax.jacfwd(rate, argnums=(0, 1))(x0, f0)
    forced = jnp.stack([jnp.imag(c), jnp.real(c)], axis=-1).reshape(-1)  # (2J,)
    return jnp.concatenate([A, d[:, None], b[:, None] * forced[None, :]], axis=1)


def _exact_flight(system, forcing, mode, scale, x, t, tau):
    """``exact_flight`` differentiated through the exponential (its Fréchet derivative)."""
    one = lambda v: jnp.asarray(v)[None]  # noqa: E731
    return flight_linearizations(system, forcing, one(mode), scale, x[None], one(t),
                                 one(tau))[0][0]


@eqx.filter_custom_jvp
def exact_flight(system, forcing, mode, scale, x, t, tau):
    """Scaled state ``x`` (by ``scale``) at time ``t`` [s] carried ``tau`` [s] in the affine
    ``mode`` with no event: ``e^{Âτ} z`` (``expm``), differentiable in everything.

    Its JVP (``_exact_flight_jvp``) takes the tangents in the state and the times in
    closed form, ``dy = [e^{Âτ} dz + Â e^{Âτ} z dτ]_{1..n}`` with ``dz`` the augmented
    state's tangent in ``x`` and ``t`` (``Â`` is time-invariant and commutes with its
    exponential): one exponential serves every direction.  Where the forcing frequency
    alone moves the exponent (``_frequency_jvp``), one exponential of ``2J`` more rows
    serves every direction too; where other parameters (system, forcing) carry tangents,
    the JVP is the Fréchet derivative's.  A fixed-sequence solve
    (``_continuation.sequence``) differentiates in states and event times alone."""
    return _exact_flight(system, forcing, mode, scale, x, t, tau)


@exact_flight.def_jvp
def _exact_flight_jvp(primals, tangents):
    system, forcing, mode, scale, x, t, tau = primals
    t_sys, t_forc, _, t_scale, dx, dt, dtau = tangents
    if any(leaf is not None for leaf in jax.tree_util.tree_leaves(
            (t_sys, t_forc, t_scale), is_leaf=lambda a: a is None)):
        if _moves_frequency_alone(system, forcing, t_sys, t_forc):
            return _frequency_jvp(primals, tangents)
        # the parameters move the exponent: the Fréchet derivative, in every direction
        return eqx.filter_jvp(_exact_flight, primals, tangents)
    n = x.shape[0]
    ratio = scale / system.state_scale(forcing)
    A, E = (v[0] for v in _exponentials(system, forcing, jnp.asarray(mode)[None],
                                        jnp.asarray(t)[None], jnp.asarray(tau)[None]))
    z, dz = jax.jvp(lambda x_, t_: augmented_state(x_ * ratio, forcing, t_), (x, t),
                    (_zero_if_none(dx, x), _zero_if_none(dt, t)))
    Ez = E @ z
    dy = E @ dz + (A @ Ez) * _zero_if_none(dtau, tau)
    return Ez[:n] / ratio, dy[:n] / ratio


def _zero_if_none(tangent, primal):
    return jnp.zeros_like(primal) if tangent is None else tangent


def _frequency_jvp(primals, tangents):
    r"""``exact_flight``'s JVP where, of the parameters, only the forcing frequency ``ω``
    (and the caller's ``scale``) carries a tangent, and ``ω`` enters ``Â`` only through
    its rotation block ``ω K`` (``frequency_in_rotation_only``).

    Then ``∂Â/∂ω`` is ``K`` in the rows and columns of the oscillators, and the Fréchet
    derivative of ``e^{Âτ}`` in that direction, applied to ``z``, is
    ``W K z_osc`` with ``W = ∫_0^τ e^{Â(τ-s)} P e^{Ωs} ds`` (``P`` the oscillators' rows,
    ``Ω`` their block; ``K`` commutes with ``e^{Ωs}``): the top right block of the
    exponential of ``[[Â, P], [0, Ω]] τ`` (C. Van Loan, *Computing integrals involving
    the matrix exponential*, IEEE Trans. Automat. Control 23 (1978) 395).  One exponential
    of ``2J`` more rows serves every direction, where the Fréchet derivative would take
    one a direction.  The flight is computed on the system's own state scale held fixed
    (the flow does not depend on it).  Where the frequency carries no tangent (the
    caller's ``scale`` alone does) the plain exponential serves.  The tangent is not
    differentiable again (the exponentials are taken on values), as the replay's."""
    system, forcing, mode, scale, x, t, tau = primals
    t_sys, t_forc, _, t_scale, dx, dt, dtau = tangents
    if t_forc is None:
        t_forc = jax.tree_util.tree_map(lambda _: None, forcing)
    n = x.shape[0]
    nat = _sg(system.state_scale(forcing))
    moving = t_forc.omega is not None
    A, E, W, K = _frequency_exponential(system, forcing, mode, nat, t, tau, moving)

    def start(x_, t_, forcing_, scale_):
        return augmented_state(x_ * (scale_ / nat), forcing_, t_), scale_ / nat

    (z, ratio), (dz, dratio) = eqx.filter_jvp(start, (x, t, forcing, scale),
                                              (dx, dt, t_forc, t_scale))
    dz, dratio = _zero_if_none(dz, z), _zero_if_none(dratio, ratio)
    Ez = E @ z
    dEz = E @ dz + (A @ Ez) * _zero_if_none(dtau, tau)
    if moving:
        dEz = dEz + (W @ (K @ z[n + 1:])) * t_forc.omega
    y = Ez[:n] / ratio
    return y, (dEz[:n] - y * dratio) / ratio


def _frequency_exponential(system, forcing, mode, nat, t, tau, moving=True):
    """``(Â, e^{Âτ}, W, K)`` of one flight (``_frequency_jvp``), ``Â`` on the state scale
    ``nat`` (no tangent), ``K = ∂Ω/∂ω``; values only.  ``moving`` False: ``e^{Âτ}``
    alone (``W``, ``K`` None)."""
    system, forcing, mode, t, tau = _values((system, forcing, mode, t, tau))
    A = mode_matrix(system, forcing, mode, nat, t)
    if not moving:
        return A, expm((A * tau)[:, :, None])[:, :, 0], None, None
    orders = jnp.asarray(forcing.harmonics()[0], dtype=A.dtype)
    N, J2 = A.shape[0], 2 * orders.shape[0]
    M = jnp.zeros((N + J2, N + J2), A.dtype)
    M = M.at[:N, :N].set(A).at[N - J2:N, N:].set(jnp.eye(J2, dtype=A.dtype))
    M = M.at[N:, N:].set(A[N - J2:, N - J2:])
    X = expm((M * tau)[:, :, None])[:, :, 0]
    return A, X[:N, :N], X[:N, N:], _rotation(orders, A.dtype)


def _moves_frequency_alone(system, forcing, t_sys, t_forc):
    """Whether the tangents ``(t_sys, t_forc)`` of ``exact_flight``'s system and forcing
    move the forcing frequency alone, in a system and forcing where it enters the mode
    matrices through their rotation block only (``_frequency_jvp``)."""
    is_none = lambda a: a is None  # noqa: E731
    if any(a is not None for a in jax.tree_util.tree_leaves(t_sys, is_leaf=is_none)):
        return False
    leaf = frequency_leaf(forcing)
    if leaf is None:
        return False
    tl = jax.tree_util.tree_leaves(t_forc, is_leaf=is_none)
    return (all(a is None for i, a in enumerate(tl) if i != leaf)
            and frequency_in_rotation_only(system, forcing))


def frequency_leaf(forcing):
    """The index of ``forcing.omega`` among the forcing's leaves (``None`` counted as
    leaves), or ``None`` where the frequency is not a field of its own."""
    is_none = lambda a: a is None  # noqa: E731
    mark = object()
    try:
        marked = eqx.tree_at(lambda f: f.omega, forcing, replace=mark, is_leaf=is_none)
    except Exception:  # noqa: BLE001 - a frequency computed by a property: not a leaf
        return None
    hits = [i for i, a in enumerate(jax.tree_util.tree_leaves(marked, is_leaf=is_none))
            if a is mark]
    return hits[0] if len(hits) == 1 else None


def frequency_in_rotation_only(system, forcing) -> bool:
    """Whether the forcing frequency ``ω`` enters the mode matrices ``Â`` of ``system``
    (on a fixed state scale) only through the oscillators' rotation block: checked on
    the traced program of ``Â``'s other rows as a function of ``ω`` and the mode (a
    forcing whose coefficients depend on ``ω``, or modes that read it, fail)."""
    system, forcing = _values((system, forcing))
    nat = system.state_scale(forcing)
    if frequency_leaf(forcing) is None:
        return False

    def top(omega, mode):
        f = eqx.tree_at(lambda f_: f_.omega, forcing, omega)
        return _mode_rows(system, f, mode, nat, 0.0)

    try:
        mode = jax.eval_shape(lambda: system.mode_of(0.0, jnp.zeros_like(nat), forcing))
        return not _depends_on_first(top, jnp.asarray(forcing.omega, dtype=float),
                                     jnp.zeros(mode.shape, mode.dtype))
    except Exception:  # noqa: BLE001 - a forcing that cannot trace ω: the replay serves
        return False


def _depends_on_first(fn, *args) -> bool:
    """Whether the traced program of ``fn(*args)`` computes any output from its first
    argument (a dataflow check of the jaxpr, nested programs counted whole)."""
    from jax.extend.core import Var
    jaxpr = jax.make_jaxpr(fn)(*args).jaxpr
    live = set(jax.tree_util.tree_leaves(jaxpr.invars[:len(jax.tree_util.tree_leaves(
        args[0]))]))
    for eqn in jaxpr.eqns:
        if any(isinstance(v, Var) and v in live for v in eqn.invars):
            live.update(eqn.outvars)
    return any(isinstance(v, Var) and v in live for v in jaxpr.outvars)


def flight_linearizations(system, forcing, modes, scale, xs, ts, taus):
    """Segments ``j`` (a batch: ``modes``, start states ``xs`` scaled by ``scale``, start
    times ``ts`` [s], durations ``taus`` [s]) flown exactly: ``(xe, Phi)``, ``xe[j] =
    e^{Âτ} z`` at the end of segment ``j`` (differentiable in everything: in the
    parameters through ``Â``, the forcing and ``scale``) and ``Phi[j]`` its derivative in
    the start state (a value), ``diag(1/r) [e^{Âτ}]_{1..n,1..n} diag(r)`` with ``r`` the
    ratio of ``scale`` to the system's own state scale.  One batched exponential
    (``expm``) serves the whole batch."""
    n = xs.shape[-1]
    ratio = scale / system.state_scale(forcing)
    _, E = _exponentials(system, forcing, modes, ts, taus)
    z = jax.vmap(lambda x, t: augmented_state(x * ratio, forcing, t))(xs, ts)
    r = _sg(ratio)
    Phi = _sg(E[:, :n, :n]) * (r[None, :] / r[:, None])
    return jnp.einsum("jkl,jl->jk", E[:, :n], z) / ratio, Phi


def _exponentials(system, forcing, modes, ts, taus):
    """``(Â, e^{Âτ})`` of a batch of segments (``modes``, start times ``ts`` [s], durations
    ``taus`` [s]) on the system's own state scale, batch first: one batched exponential."""
    nat = system.state_scale(forcing)
    A = jax.vmap(lambda m, t: mode_matrix(system, forcing, m, nat, t))(modes, ts)
    return A, jnp.moveaxis(expm(jnp.moveaxis(A * taus[:, None, None], 0, -1)), -1, 0)


def _products(A, B):
    """The products of two batches of matrices stored batch last, ``(n, m, b)`` by ``(m,
    p, b)``: sums of broadcast products, vectorized along the batch (XLA's batched dot
    runs several times slower on such small matrices)."""
    out = A[:, 0, None] * B[None, 0]
    for k in range(1, A.shape[1]):
        out = out + A[:, k, None] * B[None, k]
    return out


def _squarings(B):
    """The squarings ``s`` (one per matrix of the batch ``B``, stored batch last) that
    bring ``‖B / 2^s‖∞`` to ``NORM_BOUND`` or below; at most ``MAX_SQUARINGS`` (a
    non-finite ``B`` gives a non-finite ``e^B``, not an endless loop)."""
    norm = _sg(jnp.max(jnp.sum(jnp.abs(B), axis=1), axis=0))
    s = jnp.ceil(jnp.log2(jnp.maximum(norm, 1e-300) / NORM_BOUND))
    return jnp.where(jnp.isnan(s), 0.0, jnp.clip(s, 0.0, MAX_SQUARINGS))


def _squared(E, L, s):
    """Each matrix of ``E`` squared ``s`` times, and its Fréchet derivative ``L`` carried
    along (``(E, L) -> (E², E L + L E)``; ``L`` None: none)."""

    def body(c):
        i, E, L = c
        more = i < s
        E2 = jnp.where(more, _products(E, E), E)
        if L is not None:
            L = jnp.where(more, _products(E, L) + _products(L, E), L)
        return i + 1, E2, L

    c0 = (jnp.zeros((), s.dtype), E, L)
    return jax.lax.while_loop(lambda c: c[0] < jnp.max(s), body, c0)[1:]


def _eye(B):
    return jnp.eye(B.shape[0], dtype=B.dtype)[:, :, None]


@jax.custom_jvp
def expm(B):
    """``e^B`` for each matrix of the batch ``B`` (shape ``(n, n, b)``, batch last), of
    any norm: the Taylor polynomial of ``e^{B/2^s}`` (``TAYLOR_ORDER``, Horner's scheme)
    squared ``s`` times, ``s`` the least that brings ``‖B/2^s‖∞`` to ``NORM_BOUND`` (Moler
    and Van Loan's scaling and squaring).  Its JVP is the Fréchet derivative ``L(B, dB)``
    by the same recursion on the pair ``(E, L)``; batched over tangent directions
    (``jax.vmap``) the exponential itself is computed once, ``L`` once a direction."""
    s = _squarings(B)
    Bc = B * 2.0 ** -s
    E = jnp.broadcast_to(_eye(B), B.shape)
    for m in range(TAYLOR_ORDER, 0, -1):
        E = _eye(B) + _products(Bc / m, E)
    return _squared(E, None, s)[0]


@expm.defjvp
def _expm_jvp(primals, tangents):
    (B,), (dB,) = primals, tangents
    s = _squarings(B)
    c = 2.0 ** -s
    Bc, dBc = B * c, dB * c
    # Horner: E <- I + (Bc/m) E, so L <- (dBc E + Bc L)/m
    E, L = jnp.broadcast_to(_eye(B), B.shape), jnp.zeros_like(dB)
    for m in range(TAYLOR_ORDER, 0, -1):
        E, L = _eye(B) + _products(Bc / m, E), (_products(dBc, E) + _products(Bc, L)) / m
    return _squared(E, L, s)


def augmented_state(x, forcing, t):
    """``z = (x, 1, cos k_jωt, sin k_jωt, …)`` at time ``t`` [s]."""
    orders, _ = forcing.harmonics()
    phase = jnp.asarray(orders, dtype=float) * forcing.omega * t
    osc = jnp.stack([jnp.cos(phase), jnp.sin(phase)], axis=-1).reshape(-1)
    return jnp.concatenate([x, jnp.ones((1,), x.dtype), osc])


def expm_small(B):
    """``e^B`` for ``‖B‖∞ <= NORM_BOUND`` (Taylor, Horner's scheme)."""
    eye = jnp.eye(B.shape[-1], dtype=B.dtype)
    E = eye
    for m in range(TAYLOR_ORDER, 0, -1):
        E = eye + (B / m) @ E
    return E


def flow_small(B, z):
    """``e^B z`` for ``‖B‖∞ <= NORM_BOUND`` (Taylor, Horner's scheme on the vector)."""
    v = z
    for m in range(TAYLOR_ORDER, 0, -1):
        v = z + (B @ v) / m
    return v


def hermite_apex(p0, p1, r0, r1, xp=jnp):
    """The top of the cubic Hermite interpolant on ``[0, 1]`` of values ``p0``, ``p1`` and
    rates ``r0 > 0 >= r1`` (per unit interval): ``(τ, height)``, ``τ`` the root of its
    derivative in ``[0, 1]`` (0.5 where none is found) and the height there."""
    # H(τ) = (2τ³ - 3τ² + 1) p0 + (τ³ - 2τ² + τ) r0 + (-2τ³ + 3τ²) p1 + (τ³ - τ²) r1;
    # H'(τ) = a τ² + b τ + c
    a = 6 * (p0 - p1) + 3 * (r0 + r1)
    b = 6 * (p1 - p0) - 4 * r0 - 2 * r1
    c = r0
    disc = xp.sqrt(xp.maximum(b * b - 4 * a * c, 0.0))
    q = -0.5 * (b + xp.where(b < 0, -1.0, 1.0) * disc)
    safe = lambda d: xp.where(d == 0, 1.0, d)  # noqa: E731
    roots = xp.stack([xp.where(a == 0, xp.inf, q / safe(a)), xp.where(q == 0, xp.inf, c / safe(q))])
    inside = (roots >= 0) & (roots <= 1)
    tau = xp.where(inside[0], roots[0], xp.where(inside[1], roots[1], 0.5))
    tau = xp.clip(tau, 0.0, 1.0)
    height = ((2 * tau**3 - 3 * tau**2 + 1) * p0 + (tau**3 - 2 * tau**2 + tau) * r0
              + (-2 * tau**3 + 3 * tau**2) * p1 + (tau**3 - tau**2) * r1)
    return tau, height


def _powers(E, count):
    """``E, E², …, E^count`` (``count`` a power of two), by doubling."""
    P = E[None]
    while P.shape[0] < count:
        P = jnp.concatenate([P, jnp.einsum("ij,kjl->kil", P[-1], P)], axis=0)
    return P


def in_closed_form(system, forcing) -> bool:
    """Whether the flights of hybrid ``system`` under ``forcing`` are integrated in closed
    form: affine modes and a periodic forcing whose harmonics are exact."""
    return (bool(system.affine_modes) and isinstance(forcing, AbstractPeriodicForcing)
            and bool(forcing.harmonics_exact))


def _sg(x):
    return jax.lax.stop_gradient(x)


def _values(tree):
    """``tree`` with its arrays' tangents stopped (other leaves as they are)."""
    return jax.tree_util.tree_map(lambda a: _sg(a) if eqx.is_array(a) else a, tree)


def closed_form_segment(system, forcing, scale, t0, t1, ts, h_max, max_nodes, free_mode):
    """The segment function of ``hybrid_solve`` for systems with affine modes: from scaled
    state ``x`` at time ``t`` [s] in ``mode`` to the first upward crossing of the switching
    function ``system.switch_function`` past its start value ``start`` (or to ``t1``), the
    save times ``ts`` it passes written into ``ys``.

    Returns ``(t_end, x_end, hit, status, nodes, ys)``: the located event time (no
    tangent) or ``t1``; the state there with its tangent at fixed time; whether an event
    ended it; the status; the nodes evaluated; the samples.  The nodes lie on the grid
    ``t0 + j h`` of the whole integration (``h``: ``h_max`` divided by the smallest
    integer that bounds ``‖Â h‖∞``), so that save times on that grid are nodes.
    ``max_nodes``: the node budget of one segment.  The node operators of ``free_mode``
    (every contact open, the commonest) are computed once per integration.

    Without save times (a period map, shooting's and continuation's Jacobians) the
    segment carries a custom JVP (``_flight``): the windows run on values alone and the
    tangent is that of ``e^{Â τ} z`` over the segment's duration ``τ``, one exponential
    and its Fréchet derivative, instead of forward mode through every window."""
    grid = (_sg(t0), _sg(t1), _sg(h_max))
    if ts is None:
        free = _operators(*_values((system, forcing)), free_mode, grid)

        def run(t, x, mode, ys, start):
            return _flight(system, forcing, scale, x, t, mode, start, free, grid,
                           max_nodes=max_nodes) + (ys,)

        return run
    free = _operators(system, forcing, free_mode, grid)

    def run(t, x, mode, ys, start):
        return _windows(system, forcing, scale, x, t, mode, start, free, grid, max_nodes,
                        ts, ys)

    return run


def _operators(system, forcing, mode, grid):
    """``Â`` of ``mode`` on the system's own state scale, the node spacing ``h`` and the
    node operators ``I, E, …, E^(NODES-1)``, ``E = e^{Âh}``."""
    t0b, _, h_max = grid
    A = mode_matrix(system, forcing, mode, system.state_scale(forcing), t0b)
    norm = _sg(jnp.max(jnp.sum(jnp.abs(A), axis=1)))
    h = h_max / jnp.maximum(jnp.ceil(norm * h_max / NORM_BOUND), 1.0)
    E = expm_small(A * h)
    P = jnp.concatenate([jnp.eye(E.shape[0], dtype=E.dtype)[None],
                         _powers(E, NODES)[:-1]], axis=0)
    return A, h, P


@eqx.filter_custom_jvp
def _flight(system, forcing, scale, x, t, mode, start, free, grid, *, max_nodes):
    """``_windows`` without save times: ``(t_end, x_end, hit, status, nodes)``; its JVP
    (``_flight_jvp``) is that of the exact flow over the segment."""
    return _windows(system, forcing, scale, x, t, mode, start, free, grid, max_nodes, None,
                    None)[:5]


@_flight.def_jvp
def _flight_jvp(primals, tangents, *, max_nodes):
    r"""The segment's state at its located time ``t_end`` (held fixed: ``hybrid_solve``
    adds the event time's own tangent) is ``x_end = [e^{Â τ} z(x)]_{1..n}``, ``τ = t_end -
    t``, ``z(x)`` the augmented start state; its tangent in the state, the system and the
    forcing is the JVP of that expression (``expm`` differentiates by the Fréchet derivative
    of the exponential).  Neither the start time
    nor the located time carries a tangent."""
    system, forcing, scale, x, t, mode, start, free, grid = primals
    out = _flight(*primals, max_nodes=max_nodes)
    tau = _sg(out[0] - t)
    t_b, mode_b = _sg(t), _sg(mode)

    def exact(system, forcing, scale, x):
        return exact_flight(system, forcing, mode_b, scale, x, t_b, tau)

    _, dx_end = eqx.filter_jvp(exact, (system, forcing, scale, x), tangents[:4])
    return out, (None, dx_end, None, None, None)


def _windows(system, forcing, scale, x, t, mode, start, free, grid, max_nodes, ts, ys):
    """The closed-form segment (``closed_form_segment``) from ``x`` at ``t`` in ``mode``,
    window after window of ``NODES`` nodes; ``free``: the all-open mode's operators
    (``_operators``); ``grid``: ``(t0, t1, h_max)``, no tangents."""
    n = scale.shape[0]
    t0b, t1b, _ = grid
    free_mode = jnp.zeros_like(mode)
    # the flights run on the system's own state scale (‖Â‖ then ~ the motion's rates,
    # whatever the caller's scale)
    nat = system.state_scale(forcing)
    ratio = scale / nat
    ts_b = None if ts is None else _sg(ts)
    slots = NODES

    def switch(tt, xx, mm):
        return system.switch_function(tt, xx * scale, forcing, mm)

    def near(z, d, A, h):
        """``e^{A d} z``: one first-order step where ``|d|`` is a rounding of the node grid,
        else the Taylor flow."""
        return jax.lax.cond(jnp.abs(d) <= NODE_SLACK * h, lambda: z + d * (A @ z),
                            lambda: flow_small(A * d, z))

    def run(t, x, mode, ys, start):
        A, h, P = jax.lax.cond(jnp.all(mode == free_mode), lambda: free,
                               lambda: _operators(system, forcing, mode, grid))
        A_b = _sg(A)

        def g_of(tt, z):
            return switch(tt, z[:n] / ratio, mode) - start

        def gdot_of(tt, z):
            return jax.jvp(lambda t_, x_: switch(t_, x_ / ratio, mode), (tt, z[:n]),
                           (jnp.ones_like(tt), (A_b @ z)[:n]))[1]

        def gddot_of(tt, z):
            return jax.jvp(gdot_of, (tt, z), (jnp.ones_like(tt), A_b @ z))[1]

        def window(c):
            tw, zw, ys, nodes, _, _, _ = c
            # the first node at or after tw, then NODES - 1 more, h apart
            n1 = t0b + h * jnp.ceil((tw - t0b) / h - NODE_SLACK)
            n1 = jnp.maximum(n1, tw)
            Z = P @ near(zw, n1 - tw, A, h)                  # (NODES, N)
            tn = n1 + h * jnp.arange(NODES)
            # the window ends at its last node, at t1, or at its last save slot
            te = jnp.minimum(tn[-1], t1b)
            if ts is not None:
                i0 = jnp.searchsorted(ts_b, tw, side="left")
                cut = jnp.where(i0 + slots - 1 < ts_b.shape[0],
                                ts_b[jnp.minimum(i0 + slots - 1, ts_b.shape[0] - 1)], jnp.inf)
                te = jnp.where(cut > tw, jnp.minimum(te, cut), te)
            # the nodes before te (one on te, to rounding, is te's own point)
            valid = tn < te - NODE_SLACK * h
            j_last = jnp.sum(valid)
            z_last = jnp.where(j_last > 0, Z[jnp.maximum(j_last - 1, 0)], zw)
            t_last = jnp.where(j_last > 0, tn[jnp.maximum(j_last - 1, 0)], tw)
            on = jnp.minimum(j_last, NODES - 1)
            z_end = jnp.where(j_last < NODES, near(Z[on], te - tn[on], A, h),
                              near(z_last, te - t_last, A, h))
            # the window's points: its start, the nodes before te, te; each point's
            # predecessor (te's is the last node before it)
            pt = jnp.concatenate([tw[None], tn, te[None]])
            pz = jnp.concatenate([zw[None], Z, z_end[None]], axis=0)
            live = jnp.concatenate([valid, jnp.ones((1,), bool)])
            prev = jnp.concatenate([jnp.arange(NODES), j_last[None]])
            g = jax.vmap(g_of)(pt, _sg(pz))
            gd = jax.vmap(gdot_of)(pt, _sg(pz))
            ga, gda, ta_all = g[prev], gd[prev], pt[prev]
            g1, gd1 = g[1:], gd[1:]
            dt = pt[1:] - ta_all
            cross = live & (g1 > 0)
            # an apex of g between two points below zero: the switch may have crossed and
            # crossed back between them; checked where the cubic through their values
            # and rates comes within APEX_MARGIN of zero
            _, height = hermite_apex(ga, g1, gda * dt, gd1 * dt)
            apex = live & (gda > 0) & (gd1 < 0) & (height > -APEX_MARGIN)
            flag = cross | apex
            flagged = jnp.any(flag)
            k = jnp.argmax(flag)
            ta, za, tb = ta_all[k], pz[prev[k]], pt[k + 1]

            def top():
                # the apex itself (ġ falls through zero) and the switch there
                t_top = _upcrossing(lambda tt, z: -gdot_of(tt, z),
                                    lambda tt, z: -gddot_of(tt, z), A_b, ta, _sg(za), tb,
                                    -gda[k], -gd1[k])
                return t_top, g_of(t_top, flow_small(A_b * (t_top - ta), _sg(za)))

            # a crossing at point k + 1, else (an apex flagged) the crossing before the apex
            t_top, g_top = jax.lax.cond(flagged & ~cross[k], top, lambda: (tb, g1[k]))
            found = flagged & (cross[k] | (g_top > 0))
            t_hit = jax.lax.cond(found, lambda: _upcrossing(g_of, gdot_of, A_b, ta, _sg(za),
                                                            t_top, ga[k], g_top),
                                 lambda: te)
            # an apex clear of the wall ends the window at the point after it; the flow to
            # the event only where there is one
            t_stop = jnp.where(found, t_hit, jnp.where(flagged, tb, te))
            z_stop = jax.lax.cond(found, lambda: flow_small(A * (t_stop - ta), za),
                                  lambda: jnp.where(flagged, pz[k + 1], z_end))
            final = ~found & (t_stop >= t1b)
            if ts is not None:
                ys = _samples(A, ys, ts_b, i0, tw, zw, tn, Z, j_last, t_stop, final, h, ratio)
            return t_stop, z_stop, ys, nodes + j_last + 1, found, final, jnp.all(
                jnp.isfinite(_sg(z_stop)))

        def cond(c):
            _, _, _, nodes, found, at_end, finite = c
            return ~found & ~at_end & finite & (nodes < max_nodes)

        z0 = augmented_state(x * ratio, forcing, t)
        c0 = (t, z0, ys, jnp.zeros((), int), jnp.zeros((), bool), t >= t1b,
              jnp.ones((), bool))
        t_end, z_end, ys, nodes, found, at_end, finite = jax.lax.while_loop(cond, window, c0)
        status = jnp.where(~finite, Status.SOLVER_FAILED,
                           jnp.where(found | at_end, Status.SUCCESS, Status.MAX_STEPS))
        return t_end, z_end[:n] / ratio, found, status, nodes, ys

    return run(t, x, mode, ys, start)


def _samples(A, ys, ts_b, i0, tw, zw, tn, Z, j_last, t_stop, final, h, ratio):
    """``ys`` with the save times of a window's slots ``i0, i0 + 1, …`` that lie in
    ``[tw, t_stop)`` (``t_stop`` too when ``final``) written: each from the node at or
    before it (the window's start before its first node), exactly on the node grid, else
    by ``e^{Aδ}``; states divided by ``ratio`` back to the caller's scale."""
    slot = i0 + jnp.arange(NODES)
    real = slot < ts_b.shape[0]
    idx = jnp.minimum(slot, ts_b.shape[0] - 1)
    tau = ts_b[idx]
    inside = real & (tau >= tw) & ((tau < t_stop) | (final & (tau <= t_stop)))
    j = jnp.floor((tau - tn[0]) / h + NODE_SLACK).astype(int)
    j = jnp.clip(j, -1, jnp.maximum(j_last - 1, -1))
    base = jnp.where((j >= 0)[:, None], Z[jnp.maximum(j, 0)], zw[None])
    t_base = jnp.where(j >= 0, tn[jnp.maximum(j, 0)], tw)
    delta = jnp.where(inside, tau - t_base, 0.0)
    # on the node grid (up to rounding) one first-order step is exact to O(δ²)
    off_grid = jnp.any(jnp.abs(delta) > NODE_SLACK * h)
    zs = jax.lax.cond(
        off_grid,
        lambda: jax.vmap(lambda d, zb: flow_small(A * d, zb))(delta, base),
        lambda: base + delta[:, None] * (base @ A.T))
    # slots past the last save time are dropped (their clipped index repeats the last one)
    return ys.at[jnp.where(real, slot, ts_b.shape[0])].set(
        jnp.where(inside[:, None], zs[:, :ratio.shape[0]] / ratio, ys[idx]), mode="drop")


def _upcrossing(g_of, gdot_of, A, ta, za, tb, g_a, g_b):
    """The upcrossing of ``g`` in ``(ta, tb]`` along the flow ``e^{A(τ - ta)} za``
    (``g_a = g(ta) <= 0 < g_b = g(tb)``, known to the caller): the bracket's upper end
    once its Newton correction ``g/ġ`` is below the rounding of the time there, or the
    bracket is; Newton steps, bisection where one leaves the bracket (no tangents)."""

    def at(tau):
        z = flow_small(A * (tau - ta), za)
        return g_of(tau, z), gdot_of(tau, z)

    def body(c):
        lo, hi, tau, i, _, nudge = c
        g, gd = at(tau)
        lo = jnp.where(g <= 0, tau, lo)
        hi = jnp.where(g > 0, tau, hi)
        # converged on the crossing's upper side (g rises through zero there; a start on
        # the wall, g(ta) = 0, is not the crossing) to a Newton correction below the
        # rounding of t (a slow impact's g is small long before its time is exact), or the
        # bracket is at rounding
        ulp = 4 * jnp.finfo(hi.dtype).eps * jnp.abs(hi)
        newton = tau - g / jnp.where(gd == 0, 1.0, gd)
        # Newton converged from below (g <= 0, its correction within rounding) steps up
        # by the rounding tolerance, doubled at each such step in a row (g's own rounding
        # can hold it below zero over a few of them): on the upper side the bracket is
        # then within rounding, where bisection from the far end would halve it ~30 times
        below = (g <= 0) & (gd > 0) & (newton - tau < ulp)
        nudge = jnp.where(below, jnp.where(nudge > 0, 2 * nudge, ulp), 0.0)
        newton = jnp.where(below, tau + nudge, newton)
        inside = (newton > lo) & (newton < hi) & (gd != 0)
        nxt = jnp.where(inside, newton, 0.5 * (lo + hi))
        done = ((g > 0) & (g <= jnp.abs(gd) * ulp)) | (hi - lo <= ulp)
        return lo, hi, nxt, i + 1, done, nudge

    def cond(c):
        return ~c[4] & (c[3] < LOCATE_ITERATIONS)

    guess = ta + (tb - ta) * (-g_a) / jnp.where(g_b - g_a > 0, g_b - g_a, 1.0)
    guess = jnp.clip(guess, ta, tb)
    zero = jnp.zeros((), ta.dtype)
    return jax.lax.while_loop(cond, body, (ta, tb, guess, 0, jnp.zeros((), bool), zero))[1]
