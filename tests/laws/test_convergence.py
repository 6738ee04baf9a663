"""The smoothed model converges to independent event-exact references as eps -> 0, at the
rates measured while planning: eps² for the Kelvin–Voigt impact scene, eps for Coulomb."""

import numpy as np
import references as R

import absorber_jax as aj


def _rate(eps, err):
    return np.polyfit(np.log(eps), np.log(err), 1)[0]


def test_kelvin_voigt_impact_converges_like_eps_squared():
    ts = np.linspace(0.0, 1.0, 2001)
    x1_ref, x2_ref = R.impact_kelvin_voigt(1.0, 1e3, 0.1, 0.4, 1e-3, 400.0, 20.0, 2.0, 47.4, ts)
    eps_list = np.array([1e-4, 1e-5, 1e-6])
    errs = []
    for eps in eps_list:
        system, forcing = aj.presets.impact("kelvin_voigt", eps=eps)
        tr = aj.simulate(system, forcing, 1.0, ts=ts, rtol=1e-10, atol=1e-13)
        errs.append(np.max(np.abs(np.asarray(tr.x1) - x1_ref)) / np.max(np.abs(x1_ref)))
        assert np.max(np.abs(np.asarray(tr.x2) - x2_ref)) / np.max(np.abs(x2_ref)) < 10 * errs[-1]
    errs = np.array(errs)
    assert np.all(np.diff(errs) < 0)
    rate = _rate(eps_list, errs)
    assert 1.8 < rate < 2.3, (rate, errs)
    # the default eps (1e-6 m) is accurate to a few 1e-6 of the amplitude
    assert errs[-1] < 5e-6, errs


def test_coulomb_stick_slip_converges_like_eps():
    ts = np.linspace(0.0, 1.0, 2001)
    x1_ref, _ = R.friction_coulomb(1.0, 1e4, 0.0, 1.0, 1e4, 0.0, 0.5, 2.0, 10.0, 50.0, ts)
    eps_list = np.array([3e-3, 1e-3, 3e-4, 1e-4])
    errs = []
    for eps in eps_list:
        system = aj.FrictionAbsorber(m1=1.0, k1=1e4, c1=0.0, m2=1.0, k2=1e4, c2=0.0,
                                     normal_force=2.0, friction=aj.Coulomb(mu=0.5, eps=eps))
        tr = aj.simulate(system, aj.Harmonic(amplitude=10.0, omega=50.0), 1.0, ts=ts,
                         rtol=1e-10, atol=1e-13)
        errs.append(np.max(np.abs(np.asarray(tr.x1) - x1_ref)) / np.max(np.abs(x1_ref)))
    errs = np.array(errs)
    assert np.all(np.diff(errs) < 0), errs
    rate = _rate(eps_list, errs)
    assert 0.6 < rate < 1.3, (rate, errs)
    assert errs[-1] < 2e-3, errs  # default eps = 1e-4 m/s
    # the reference really does stick and slip: both phases occur
    tr = aj.simulate(system, aj.Harmonic(amplitude=10.0, omega=50.0), 1.0, ts=ts)
    frac = float(np.mean(np.asarray(tr.sliding)))
    assert 0.1 < frac < 0.9
