"""Bad input is rejected before anything is compiled, with a ValueError naming the field
and the allowed range."""

import jax.numpy as jnp
import numpy as np
import pytest

import absorber_jax as aj

KV = dict(stiffness=400.0, damping=20.0)


def impact(**kw):
    base = dict(M=1.0, k=1e3, c=0.1, m=0.4, gap=1e-3, contact=aj.KelvinVoigt(**KV))
    base.update(kw)
    return aj.ImpactAbsorber(**base)


def friction(**kw):
    base = dict(m1=1.0, k1=1e4, c1=0.0, m2=1.0, k2=1e4, c2=0.0, normal_force=2.0,
                friction=aj.Coulomb(mu=0.5))
    base.update(kw)
    return aj.FrictionAbsorber(**base)


@pytest.mark.parametrize(
    "make, match",
    [
        # masses zero or negative
        (lambda: impact(M=0.0), r"ImpactAbsorber\.M must be in \(0, inf\)"),
        (lambda: impact(m=-0.4), r"ImpactAbsorber\.m must be in \(0, inf\)"),
        (lambda: friction(m2=0.0), r"FrictionAbsorber\.m2 must be in \(0, inf\)"),
        # negative stiffness or damping
        (lambda: impact(k=-1.0), r"ImpactAbsorber\.k must be in \[0, inf\)"),
        (lambda: friction(c2=-1.0), r"FrictionAbsorber\.c2 must be in \[0, inf\)"),
        (lambda: aj.KelvinVoigt(stiffness=-400.0, damping=20.0,
                                adhesive=True), r"KelvinVoigt\.stiffness"),
        (lambda: aj.HuntCrossley(stiffness=3260.0, damping=-1.0,
                                 adhesive=True), r"HuntCrossley\.damping"),
        (lambda: impact(gap=-1e-3), r"ImpactAbsorber\.gap must be in \[0, inf\)"),
        (lambda: friction(normal_force=-1.0), r"FrictionAbsorber\.normal_force"),
        # eps <= 0
        (lambda: aj.Hertz(stiffness=3260.0, damping=20.0, eps=0.0,
                          adhesive=True), r"Hertz\.eps must be in \(0"),
        (lambda: aj.Coulomb(mu=0.5, eps=-1e-4), r"Coulomb\.eps must be in \(0"),
        (lambda: aj.Dahl(mu_c=0.5, sigma0=1e4, eps=-1e-4), r"Dahl\.eps"),
        # mu_s < mu_c
        (lambda: aj.Stribeck(mu_c=0.5, mu_s=0.4, v_s=1e-2), r"Stribeck\.mu_s must be in \[0\.5"),
        (lambda: aj.LuGre(mu_c=0.5, mu_s=0.3, v_s=1e-2, sigma0=1e4, sigma1=1e2),
         r"LuGre\.mu_s must be in \[0\.5"),
        # restitution outside (0, 1]
        (lambda: aj.hunt_crossley_damping(3260.0, 0.0, 1.0), r"restitution must be in \(0, 1\]"),
        (lambda: aj.hunt_crossley_damping(3260.0, 1.2, 1.0), r"restitution must be in \(0, 1\]"),
        # non-finite values
        (lambda: impact(c=float("nan")), r"ImpactAbsorber\.c must be finite"),
        (lambda: aj.Harmonic(amplitude=float("inf"), omega=10.0), r"Harmonic\.amplitude"),
        # wrong shapes / types
        (lambda: impact(M=jnp.ones(3)), r"ImpactAbsorber\.M must be a scalar"),
        (lambda: aj.Harmonic(amplitude=1.0, omega=[1.0, 2.0]), r"Harmonic\.omega must be a scalar"),
        (lambda: impact(contact=aj.Coulomb(mu=0.5)), r"contact must be a contact law"),
        (lambda: friction(friction=aj.KelvinVoigt(**KV)), r"friction must be a friction law"),
        (lambda: aj.Harmonic(amplitude=1.0, omega=0.0), r"Harmonic\.omega must be in \(0"),
    ],
)
def test_bad_constructor_input(make, match):
    with pytest.raises(ValueError, match=match):
        make()


def test_bad_simulate_input():
    system, forcing = aj.presets.impact("kelvin_voigt")
    with pytest.raises(ValueError, match=r"simulate\.t1 must be in \(0"):
        aj.simulate(system, forcing, -1.0)
    with pytest.raises(ValueError, match=r"y0 must have shape \(4,\)"):
        aj.simulate(system, forcing, 1.0, y0=jnp.zeros(5))
    with pytest.raises(ValueError, match="y0 must be finite"):
        aj.simulate(system, forcing, 1.0, y0=jnp.array([0.0, np.nan, 0.0, 0.0]))
    with pytest.raises(ValueError, match="ts must be strictly increasing"):
        aj.simulate(system, forcing, 1.0, ts=jnp.array([0.0, 0.5, 0.2]))
    with pytest.raises(ValueError, match=r"ts must lie in \[t0, t1\]"):
        aj.simulate(system, forcing, 1.0, ts=jnp.array([0.0, 2.0]))
    with pytest.raises(ValueError, match=r"Integrator\.rtol must be in \(0, 1\)"):
        aj.simulate(system, forcing, 1.0, integrator=aj.Integrator(rtol=0.0))
    with pytest.raises(ValueError, match="solver must be one of"):
        aj.simulate(system, forcing, 1.0, solver="euler-ish")
    # KenCarp is not offered (it failed on every scene), by name or as an object
    with pytest.raises(ValueError, match="solver must be one of"):
        aj.simulate(system, forcing, 1.0, solver="kencarp4")
    import diffrax

    with pytest.raises(ValueError, match="KenCarp4 is not supported"):
        aj.simulate(system, forcing, 1.0, solver=diffrax.KenCarp4())
    # energy bookkeeping needs the smoothed law; the exact one says so
    with pytest.raises(ValueError, match="energy=True is not available"):
        aj.simulate(friction(), aj.Harmonic(amplitude=1.0, omega=50.0), 1.0, energy=True)
    with pytest.raises(ValueError, match="system must be"):
        aj.simulate(forcing, forcing, 1.0)


def test_max_steps_is_flagged_not_silent():
    system, forcing = aj.presets.impact("kelvin_voigt")
    tr = aj.simulate(system, forcing, 1.0, integrator=aj.Integrator(max_steps=5), throw=False)
    assert int(tr.status) == aj.Status.MAX_STEPS
    assert not bool(tr.ok)
    assert "max_steps" in aj.describe(tr.status)
    with pytest.raises(RuntimeError, match="max_steps"):
        aj.simulate(system, forcing, 1.0, integrator=aj.Integrator(max_steps=5))


def test_float32_is_refused_with_a_clear_error():
    """absorber_jax is float64-only: with x64 switched off every entry point refuses."""
    import subprocess
    import sys

    code = (
        "import warnings; warnings.simplefilter('ignore')\n"
        "import jax, numpy as np, absorber_jax as aj\n"
        "s, f = aj.presets.impact('kelvin_voigt')\n"
        "jax.config.update('jax_enable_x64', False)\n"
        "for call in (lambda: aj.simulate(s, f, 0.1), lambda: aj.steady_state(s, f),\n"
        "             lambda: aj.frequency_response(s, [40.0], amplitude=2.0),\n"
        "             lambda: aj.tune(s, ['k1'], (30, 40), amplitude=2.0)):\n"
        "    try:\n"
        "        call(); print('NO ERROR')\n"
        "    except ValueError as e:\n"
        "        assert 'needs float64' in str(e), e\n"
        "print('refused')\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "NO ERROR" not in out.stdout and "refused" in out.stdout


def test_methods_are_objects_with_checked_options():
    system, forcing = aj.presets.impact("kelvin_voigt")
    with pytest.raises(ValueError, match=r"Shooting\.tol must be in \(0, inf\)"):
        aj.Shooting(tol=0.0)
    with pytest.raises(ValueError, match=r"Shooting\.n must be an integer in \[1, 64\]"):
        aj.Shooting(n=0)
    with pytest.raises(ValueError, match=r"Marching\.max_periods must be a positive integer"):
        aj.Marching(max_periods=0)
    with pytest.raises(ValueError, match="root solver must be"):
        aj.Shooting(root="bisection")
    # options go on the object, not beside it
    with pytest.raises(ValueError, match=r"give \['tol'\] on the method object"):
        aj.steady_state(system, forcing, method=aj.Shooting(), tol=1e-8)
    with pytest.raises(ValueError, match=r"method must be aj.Shooting\(...\), aj.Marching"):
        aj.frequency_response(system, [40.0, 50.0], amplitude=2.0, method="hb")
