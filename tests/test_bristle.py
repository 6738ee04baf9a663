"""Dahl and LuGre: the bristle deflection stays within its steady-state bound, and LuGre's
steady sliding force is g(v) sign(v) + σ2 v."""

import diffrax
import jax.numpy as jnp
import numpy as np
import pytest

import absorber_jax as aj


@pytest.mark.parametrize("name", ["dahl", "lugre", "lugre_physical"])
def test_bristle_deflection_bounded_in_scene(name):
    """|z| <= max g / σ0 for the exact law.  Smoothing |v| as v tanh(v/eps) (needed to keep
    true sticking) lets z_ss = g / (σ0 tanh(|v|/eps)) overshoot slightly at low speed: the
    overshoot must be small and vanish as eps -> 0."""
    overshoot = {}
    for eps in (1e-4, 1e-6):
        system, forcing = aj.presets.friction(name, ramp_time=4.0, eps=eps)
        tr = aj.simulate(system, forcing, 5.0)
        law, N = system.friction, float(system.normal_force)
        mu_max = float(getattr(law, "mu_s", law.mu_c))
        bound = mu_max * N / float(law.sigma0)
        z = np.abs(np.asarray(tr.z[:, 0]))
        assert z.max() > 0.9 * float(law.mu_c) * N / float(law.sigma0)  # bristles saturate
        overshoot[eps] = z.max() / bound - 1
    assert overshoot[1e-4] < 1e-3, overshoot
    assert overshoot[1e-6] < max(overshoot[1e-4] / 10, 1e-9), overshoot


def _steady_force(law, v, N, t1):
    term = diffrax.ODETerm(lambda t, z, a: law.state_rate(v, z, N))
    sol = diffrax.diffeqsolve(term, diffrax.Kvaerno5(), 0.0, t1, 1e-6, law.initial_state(),
                              stepsize_controller=diffrax.PIDController(rtol=1e-10, atol=1e-14),
                              max_steps=100000)
    return float(law.force(v, sol.ys[-1], N))


@pytest.mark.parametrize("sigma2", [0.0, 3.0])
def test_lugre_steady_state_friction_curve(sigma2):
    N, mu_c, mu_s, v_s = 10.0, 0.5, 0.6, 1e-2
    law = aj.LuGre(mu_c=mu_c, mu_s=mu_s, v_s=v_s, sigma0=1e4, sigma1=1e2, sigma2=sigma2,
                   eps=1e-7)
    for v in [-0.2, -0.01, -3e-3, 2e-3, 1e-2, 0.05, 1.0]:
        # relax over many bristle lengths: distance |v| t >> g / σ0
        f = _steady_force(law, v, N, t1=50 * (mu_s * N / 1e4) / abs(v))
        g = N * (mu_c + (mu_s - mu_c) * np.exp(-((v / v_s) ** 2)))
        np.testing.assert_allclose(f, g * np.sign(v) + sigma2 * v, rtol=1e-6)


def test_dahl_steady_force_is_coulomb():
    law = aj.Dahl(mu_c=0.5, sigma0=1e4, eps=1e-7)
    for v in [-0.3, 0.01]:
        f = _steady_force(law, v, 8.0, t1=50 * 4.0 / 1e4 / abs(v))
        np.testing.assert_allclose(f, 4.0 * np.sign(v), rtol=1e-6)
    # and the library's own steady curve agrees
    np.testing.assert_allclose(law.steady_force(jnp.array(0.01), 8.0), 4.0)
