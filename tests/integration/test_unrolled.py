"""The unrolled Runge–Kutta solvers (absorber_jax._integration.unrolled) are diffrax's own: the same
steps, states, dense output and forward-mode derivatives, to rounding."""

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from absorber_jax._integration import unrolled as U


def _duffing(t, y, args):
    return jnp.stack([y[1], -y[0] - 0.1 * y[1] - 5.0 * y[0] ** 3 + jnp.sin(3.0 * t)])


@pytest.mark.parametrize("name", ["Tsit5", "Dopri5", "Dopri8", "Bosh3"])
def test_unrolled_solver_equals_diffrax(name):
    def solve(solver):
        def run(y0):
            sol = diffrax.diffeqsolve(
                diffrax.ODETerm(_duffing), solver, 0.0, 10.0, None, y0,
                saveat=diffrax.SaveAt(ts=jnp.linspace(0.0, 10.0, 33)),
                stepsize_controller=diffrax.PIDController(rtol=1e-8, atol=1e-8),
                adjoint=diffrax.ForwardMode())
            return sol.ys, sol.stats["num_accepted_steps"], sol.stats["num_rejected_steps"]

        y0 = jnp.array([1.0, 0.0])
        ys, acc, rej = run(y0)
        jac = jax.jacfwd(lambda y: run(y)[0])(y0)
        batch = jax.vmap(lambda y: run(y)[0])(jnp.stack([y0, 0.5 * y0]))
        return np.asarray(ys), (int(acc), int(rej)), np.asarray(jac), np.asarray(batch)

    ref_solver = getattr(diffrax, name)()
    ours = U.unrolled(ref_solver)
    assert type(ours) is getattr(U, name) and isinstance(ours, type(ref_solver))
    ys0, steps0, jac0, batch0 = solve(ref_solver)
    ys1, steps1, jac1, batch1 = solve(ours)
    assert steps1 == steps0
    # (the states are O(1), the Jacobian up to ~10: differences are rounding, measured
    # below 6e-12)
    np.testing.assert_allclose(ys1, ys0, rtol=0, atol=1e-10)
    np.testing.assert_allclose(batch1, batch0, rtol=0, atol=1e-10)
    np.testing.assert_allclose(jac1, jac0, rtol=0, atol=1e-9)


def test_other_solvers_pass_through():
    kv = diffrax.Kvaerno5()
    assert U.unrolled(kv) is kv
