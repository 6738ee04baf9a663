"""Neutral defaults: a law a user builds never pulls at separation unless asked, dampings
default to zero, and parameter_names lists design parameters only."""

import numpy as np

import absorber_jax as aj


def test_contact_laws_do_not_pull_unless_asked():
    delta, rate = 1e-4, -1.0                 # inside the wall, leaving fast
    for cls in (aj.KelvinVoigt, aj.Hertz, aj.HuntCrossley):
        plain = cls(stiffness=1e5, damping=50.0)
        sticky = cls(stiffness=1e5, damping=50.0, adhesive=True)
        assert not plain.adhesive
        assert float(plain.force(delta, rate)) >= -1e-12      # clipped (smoothly) at zero
        elastic = 1e5 * delta ** plain.exponent
        viscous = 50.0 * rate * (delta**1.5 if cls is aj.HuntCrossley else 1.0)
        np.testing.assert_allclose(float(sticky.force(delta, rate)), elastic + viscous,
                                   rtol=1e-9)
        assert float(cls(stiffness=1e5).damping) == 0.0


def test_friction_absorber_damping_defaults_to_zero():
    law = aj.Coulomb(mu=0.5)
    a = aj.FrictionAbsorber(m1=1.0, k1=1e4, m2=0.1, k2=1e3, normal_force=2.0, friction=law)
    b = aj.FrictionAbsorber(m1=1.0, k1=1e4, c1=0.0, m2=0.1, k2=1e3, c2=0.0, normal_force=2.0,
                            friction=law)
    f = aj.Harmonic(amplitude=5.0, omega=90.0)
    np.testing.assert_array_equal(np.asarray(aj.simulate(a, f, 0.3).ys),
                                  np.asarray(aj.simulate(b, f, 0.3).ys))


def test_parameter_names_are_design_parameters():
    system, _ = aj.presets.friction("coulomb")
    names = aj.parameter_names(system)
    assert {"m2", "k2", "c2", "N", "mu"} <= set(names)
    assert not {"eps", "exact", "adhesive"} & set(names)
    impact, _ = aj.presets.impact("hertz")
    assert "eps" not in aj.parameter_names(impact)
    # settings stay replaceable by name
    assert float(aj.get_param(aj.replace_params(impact, {"eps": 1e-7}), "eps")) == 1e-7


def test_a_gap_far_beyond_the_motion_is_warned_about():
    """A clearance of 1 m on millimetre motion (a unit slip) is warned about before anything
    is computed; the paper's 1 mm clearance is not."""
    import warnings

    import pytest

    system, forcing = aj.presets.impact("kelvin_voigt")
    far = aj.replace_params(system, {"gap": 1.0})
    with pytest.warns(UserWarning, match=r"clearance of 1 m is .* the walls will not be"):
        aj.simulate(far, forcing, 0.05)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        aj.simulate(system, forcing, 0.05)
    assert not [w for w in caught if "clearance" in str(w.message)]


def test_a_frequency_far_above_the_systems_rates_is_warned_about():
    """A forcing frequency a hundred times above the system's fastest rate (a frequency in
    the wrong unit) is warned about before anything is computed; one within the modes, or
    a sweep that reaches them, is not."""
    import warnings

    import numpy as np
    import pytest

    system, _ = aj.presets.impact("kelvin_voigt")
    rate = float(system.stiffness_rate())
    with pytest.warns(UserWarning, match=r"omega = .* times the fastest rate .* rad/s"):
        aj.steady_state(system, aj.Harmonic(amplitude=2.0, omega=200.0 * rate))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        aj.steady_state(system, aj.Harmonic(amplitude=2.0, omega=0.7 * rate))
        aj.frequency_response(system, np.array([0.7, 200.0]) * rate, amplitude=2.0)
    assert not [w for w in caught if "fastest rate" in str(w.message)]
