"""With gap = 0 the Kelvin–Voigt impact scene is exactly a linear two-mass system (a tuned
mass damper); with N = 0 the friction scene is the linear k2, c2 two-mass system."""

import numpy as np
import references as R

import absorber_jax as aj


def test_zero_gap_kelvin_voigt_equals_linear_two_mass_system():
    M, k, c, m, k1, c1, F0, w = 1.0, 1e3, 0.1, 0.4, 400.0, 20.0, 2.0, 47.4
    system, forcing = aj.presets.impact("kelvin_voigt", gap=0.0, eps=1e-3)  # eps irrelevant
    ts = np.linspace(0.0, 2.0, 801)
    tr = aj.simulate(system, forcing, 2.0, ts=ts, rtol=1e-11, atol=1e-14)
    Mm = np.diag([M, m])
    Cm = np.array([[c + c1, -c1], [-c1, c1]])
    Km = np.array([[k + k1, -k1], [-k1, k1]])
    ref = R.linear_two_mass(Mm, Cm, Km, np.array([1.0, 0.0]), F0, w, ts)
    scale = np.abs(ref[:, 0]).max()
    np.testing.assert_allclose(np.asarray(tr.x1), ref[:, 0], atol=1e-8 * scale)
    np.testing.assert_allclose(np.asarray(tr.x2), ref[:, 1], atol=1e-8 * scale)


def test_zero_normal_force_friction_scene_is_linear():
    system = aj.FrictionAbsorber(m1=1.0, k1=1e4, c1=2.0, m2=0.5, k2=3e3, c2=1.0,
                                 normal_force=0.0, friction=aj.Coulomb(mu=0.5))
    forcing = aj.Harmonic(amplitude=5.0, omega=60.0)
    ts = np.linspace(0.0, 1.0, 501)
    tr = aj.simulate(system, forcing, 1.0, ts=ts, rtol=1e-11, atol=1e-14)
    Mm = np.diag([1.0, 0.5])
    Cm = np.array([[3.0, -1.0], [-1.0, 1.0]])
    Km = np.array([[1.3e4, -3e3], [-3e3, 3e3]])
    ref = R.linear_two_mass(Mm, Cm, Km, np.array([1.0, 0.0]), 5.0, 60.0, ts)
    scale = np.abs(ref[:, 0]).max()
    np.testing.assert_allclose(np.asarray(tr.x1), ref[:, 0], atol=1e-8 * scale)
    np.testing.assert_allclose(np.asarray(tr.x2), ref[:, 1], atol=1e-8 * scale)
