"""diffrax's explicit Runge–Kutta solvers with their stages unrolled.

diffrax evaluates a Runge–Kutta step's stages in a loop (``eqxi.while_loop`` over the stage
index, as a ``lax.scan`` under ``ForwardMode``), which keeps compilation small but costs a
loop iteration, a dynamic slice of the tableau and a scatter into the stage buffer per
stage.  On a state integrated alone (a large structural state's lanes run one at a time,
see ``_integration.flow.large_state``) that bookkeeping outweighs the arithmetic: one
forcing period of the 44-state building of ``scripts/benchmark_structure.py`` (Tsit5, rtol
1e-7, ~620 steps) takes 4.3 ms through diffrax's loop and 2.4 ms unrolled, the same numbers
to 1e-13.  Unrolled, the program is larger: that period compiles in 1.9 s instead of 0.9 s, a
44 × 44 monodromy in 4.0 s instead of 1.9 s.  So a large smooth state's plain integrations use them
(``_integration.flow.integrate``), and of the integrations carrying tangents only the Floquet
monodromies a sweep repeats at every point (``Config.unroll_tangents``, see
``_periodic.orbit.floquet_matrix``): with one tangent direction per row, the 44 × 44 monodromy at
rtol 1e-5 (~300 steps) takes 14 ms instead of 20 ms (17 ms unrolled with a direction per
column).  Small states, vmapped over many lanes that share the
loop's bookkeeping, keep diffrax's solvers.

The classes here are diffrax's own solvers (same tableau, same interpolation, same step-size
control, same ``isinstance`` tests) whose ``step`` writes the stages out in straight-line
code; the integration loop stays diffrax's.  Only first-same-as-last, stage-same-as-last
explicit tableaus (Tsit5, Dopri5, Dopri8, Bosh3) are unrolled: the last stage is evaluated
at ``(t1, y1)`` and its field carried to the next step.
"""

from __future__ import annotations

import dataclasses

import diffrax
import equinox.internal as eqxi
import jax
import jax.numpy as jnp
import jax.tree_util as jtu


def _combine(coeffs, ks, y0=None):
    """``y0 + Σ c_j k_j`` over the nonzero ``coeffs`` (``y0`` None: the sum alone), leaf by
    leaf of the pytrees ``ks``."""
    terms = [(float(c), k) for c, k in zip(coeffs, ks) if c != 0]

    def leaf(y, *k):
        out = y
        for (c, _), kj in zip(terms, k):
            out = c * kj if out is None else out + c * kj
        return out

    stages = [k for _, k in terms]
    if y0 is None:
        return jtu.tree_map(lambda *k: leaf(None, *k), *stages)
    return jtu.tree_map(leaf, y0, *stages)


class _UnrolledStages:
    """``step`` of a FSAL, SSAL explicit Runge–Kutta method in straight-line code (mixed into
    a diffrax solver class, before it)."""

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        if solver_state is None:
            # diffrax turned first-same-as-last off (an expensive vector field, as under
            # BacksolveAdjoint): its own step
            return super().step(terms, t0, t1, y0, args, solver_state, made_jump)
        tab = self.tableau
        first_step, f_last = solver_state
        control = terms.contr(t0, t1)
        h = t1 - t0
        # the first stage is the last step's last one, except on the first step or after a
        # jump (as diffrax: one test for the whole batch, so that the cond stays a cond)
        fresh = eqxi.unvmap_any(first_step | made_jump)
        f0 = jax.lax.cond(fresh, lambda: terms.vf(t0, y0, args), lambda: f_last)
        ks = [terms.prod(f0, control)]
        f = f0
        for a, c in zip(tab.a_lower, tab.c):
            y = _combine(a, ks, y0)
            f = terms.vf(t0 + float(c) * h, y, args)
            ks.append(terms.prod(f, control))
        # stage-same-as-last: the last stage's state is the step's result, its field the next
        # step's first stage
        y1 = y
        y_error = _combine(tab.b_error, ks)
        k = jtu.tree_map(lambda *kj: jnp.stack(kj), *ks)
        dense_info = dict(y0=y0, y1=y1, k=k)
        return y1, y_error, dense_info, (jnp.array(False), f), diffrax.RESULTS.successful


def _unrolled(cls):
    tab = cls.tableau
    assert tab.fsal and tab.ssal and not tab.implicit, cls
    return type(cls.__name__, (_UnrolledStages, cls), {
        "__module__": __name__,
        "__doc__": f"diffrax's ``{cls.__name__}`` with its stages unrolled (module docstring).",
    })


Tsit5 = _unrolled(diffrax.Tsit5)
Dopri5 = _unrolled(diffrax.Dopri5)
Dopri8 = _unrolled(diffrax.Dopri8)
Bosh3 = _unrolled(diffrax.Bosh3)


_UNROLLED = {diffrax.Tsit5: Tsit5, diffrax.Dopri5: Dopri5, diffrax.Dopri8: Dopri8,
             diffrax.Bosh3: Bosh3}


def unrolled(solver):
    """``solver`` with its stages unrolled, its options (``scan_kind``) kept (diffrax's
    Tsit5, Dopri5, Dopri8, Bosh3; any other solver as it is)."""
    cls = _UNROLLED.get(type(solver))
    if cls is None:
        return solver
    return cls(**{f.name: getattr(solver, f.name) for f in dataclasses.fields(solver)
                  if f.init})
