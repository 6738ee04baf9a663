"""One vocabulary: methods, objectives and integration settings are objects carrying their
options; entry points take them with a few keywords; the former flat keywords still give the
same numbers, with a DeprecationWarning that names the new form; an object and its own
options given as keywords at once is refused."""

import inspect
import warnings

import numpy as np
import pytest

import absorber_jax as aj

ENTRY_POINTS = ("simulate", "steady_state", "frequency_response", "continuation",
                "band_continuation", "attractors", "bifurcation_diagram", "tune",
                "value_and_grad", "exact_peak", "robust_peak")


@pytest.mark.parametrize("name", ENTRY_POINTS)
def test_entry_points_keep_few_keyword_options(name):
    params = inspect.signature(getattr(aj, name)).parameters.values()
    keywords = [p.name for p in params if p.kind is inspect.Parameter.KEYWORD_ONLY]
    assert len(keywords) <= 9, (name, keywords)
    # the same name means the same thing wherever it appears
    for shared in ("integrator", "method", "objective"):
        if shared in keywords:
            assert getattr(aj, name).__doc__.count(f"``{shared}``") >= 1, (name, shared)


def _same_with_warning(new, old, pattern):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        legacy = old()
    messages = [str(w.message) for w in caught if issubclass(w.category, DeprecationWarning)]
    assert any(pattern in m for m in messages), messages
    return new(), legacy


def test_flat_keywords_still_give_the_same_numbers_and_name_the_new_form():
    system, forcing = aj.presets.impact("kelvin_voigt")
    new, old = _same_with_warning(
        lambda: aj.steady_state(system, forcing, method=aj.Shooting(tol=1e-8),
                                integrator=aj.Integrator(rtol=1e-10, atol=1e-10)),
        lambda: aj.steady_state(system, forcing, tol=1e-8, rtol=1e-10, atol=1e-10),
        "integrator=aj.Integrator(rtol=1e-10, atol=1e-10)")
    assert float(new.amplitude) == float(old.amplitude)
    np.testing.assert_array_equal(np.asarray(new.state), np.asarray(old.state))

    new, old = _same_with_warning(
        lambda: aj.simulate(system, forcing, 0.3, integrator=aj.Integrator(rtol=1e-9)),
        lambda: aj.simulate(system, forcing, 0.3, rtol=1e-9), "aj.Integrator(rtol=1e-09)")
    np.testing.assert_array_equal(np.asarray(new.ys), np.asarray(old.ys))

    om = np.array([40.0, 47.4, 52.0])
    new, old = _same_with_warning(
        lambda: aj.frequency_response(system, om, amplitude=2.0,
                                      method=aj.Marching(max_periods=3000)),
        lambda: aj.frequency_response(system, om, amplitude=2.0, method="marching",
                                      max_periods=3000),
        "method=aj.Marching(max_periods=3000)")
    np.testing.assert_array_equal(np.asarray(new.amplitude), np.asarray(old.amplitude))


def test_an_object_and_its_options_as_keywords_are_refused():
    system, forcing = aj.presets.impact("kelvin_voigt")
    with pytest.raises(ValueError, match=r"give \['tol'\] on the method object"):
        aj.steady_state(system, forcing, method=aj.Shooting(), tol=1e-8)
    with pytest.raises(ValueError, match=r"give \['rtol'\] on the integrator"):
        aj.simulate(system, forcing, 0.1, integrator=aj.Integrator(), rtol=1e-9)
    with pytest.raises(TypeError, match="unexpected keyword argument 'tolerance'"):
        aj.steady_state(system, forcing, tolerance=1e-8)
    with pytest.raises(ValueError, match="Integrator.max_steps must be a positive integer"):
        aj.Integrator(max_steps=0)
    with pytest.raises(ValueError, match="exact_peak.objective must be an"):
        aj.exact_peak(system, (30.0, 40.0), amplitude=2.0,
                      objective=aj.objectives.SmoothPeak())


def test_one_table_of_integration_defaults():
    from absorber_jax._integration.settings import DEFAULTS

    for task, base in DEFAULTS.items():
        got = aj.Integrator().resolved(task)
        assert (got.rtol, got.atol, got.max_steps) == (base.rtol, base.atol, base.max_steps)
    # a field given wins over the task's default, the others stay
    got = aj.Integrator(rtol=1e-6).resolved("design")
    assert got.rtol == 1e-6 and got.atol == DEFAULTS["design"].atol


def test_a_design_honours_the_integrators_step_budget():
    """A step budget too small for one period reaches the design's orbit solves: every
    point fails (the budget is not silently replaced by the default)."""
    system, _ = aj.presets.impact("kelvin_voigt")
    om = np.linspace(40.0, 50.0, 3)
    _, _, ok_status = aj.value_and_grad(system, ["k1"], om, amplitude=2.0)
    assert np.all(ok_status == 0)
    _, _, status = aj.value_and_grad(system, ["k1"], om, amplitude=2.0,
                                     integrator=aj.Integrator(max_steps=3))
    assert np.all(status != 0)
