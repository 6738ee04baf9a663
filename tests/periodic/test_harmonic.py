"""Harmonic balance (``aj.HarmonicBalance``): exact on a linear structure (closed-form
receptance and Floquet exponents), converging to tightly converged shooting as the harmonics
grow (exponentially on a Duffing oscillator, algebraically on a clearance contact, NLvib
example 03's unilateral spring and a friction absorber, with the fitted rates), and its Hill
stability against shooting's Floquet multipliers on a stable and an unstable orbit."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import reference_nlvib03 as ref03
from builders import TIGHT, CubicSpring, nlvib03

import absorber_jax as aj

F0 = 5.0


def _fitted_rate(Hs, errors):
    return np.polyfit(np.log(Hs), np.log(errors), 1)[0]


def duffing():
    """``ẍ + 2ẋ + 10³ x + 10⁶ x³ = F0 sin ωt`` (m = 1 kg): folds near 52 and 39 rad/s at
    F0 = 5 N, the orbits between them unstable."""
    structure = aj.structure_from_matrices([[1.0]], [[1e3]], damping=[[2.0]], dof_names=["x"])
    return aj.StructuralSystem(structure, [CubicSpring("x", k3=1e6)], load="x")


def test_one_harmonic_is_exact_on_a_linear_oscillator():
    m, k, c, omega = 1.0, 1e3, 2.0, 25.0
    structure = aj.structure_from_matrices([[m]], [[k]], damping=[[c]], dof_names=["x"])
    system = aj.StructuralSystem(structure, [], load="x")
    ss = aj.steady_state(system, aj.Harmonic(amplitude=F0, omega=omega),
                         method=aj.HarmonicBalance(harmonics=1, tol=1e-13, condense=False,
                                                   stability="hill"))
    X = F0 / (k - m * omega**2 + 1j * c * omega)
    assert int(ss.status) == 0
    assert abs(float(ss.harmonic) / abs(X) - 1) < 1e-12
    assert abs(float(ss.amplitude) / abs(X) - 1) < 1e-7    # sampled peak-to-peak
    # the forcing F0 sin ωt: x(t) = Im(X e^{iωt}), so x(0) = Im X and v(0) = ω Re X
    assert np.allclose(np.asarray(ss.state), [X.imag, omega * X.real], rtol=1e-10, atol=0)
    # Hill's exponents are the free oscillator's: λ = -ζω0 ± iωd
    lam = np.roots([m, c, k])
    T = 2 * np.pi / omega
    expected = np.sort(np.abs(np.exp(lam * T)))
    assert np.allclose(np.sort(np.abs(np.asarray(ss.multipliers))), expected, rtol=1e-9)


def test_harmonic_balance_converges_exponentially_to_shooting_on_a_duffing_oscillator():
    # an unstable orbit between the folds, reached from a continuation point's state
    br = aj.continuation(duffing(), aj.Harmonic(amplitude=F0, omega=30.0), "omega",
                         bounds=(30.0, 60.0))
    unstable = np.flatnonzero(~np.asarray(br.stable))
    assert unstable.size
    i = unstable[unstable.size // 2]
    omega, guess = float(br.values[i]), np.asarray(br.states[i])
    forcing = aj.Harmonic(amplitude=F0, omega=omega)
    ref = aj.steady_state(duffing(), forcing, guess=guess, **TIGHT)
    assert int(ref.status) == 0 and not bool(ref.stable)
    Hs = np.array([1, 3, 5, 7, 9])
    errors = []
    for H in Hs:
        ss = aj.steady_state(duffing(), forcing, guess=guess,
                             method=aj.HarmonicBalance(harmonics=int(H), tol=1e-12,
                                                       condense=False, stability="hill"))
        assert int(ss.status) == 0
        errors.append(abs(float(ss.amplitude) / float(ref.amplitude) - 1))
        # Hill's method labels it unstable at every truncation, as Floquet does
        assert not bool(ss.stable)
    errors = np.array(errors)
    # measured: 8.6e-3, 3.7e-4, 7.3e-6, 1.4e-7, 2.6e-9 (a factor ~50 per two harmonics)
    assert np.all(np.diff(np.log(errors)) < -2.0)
    assert errors[-1] < 1e-7
    # the multipliers converge to shooting's (1.6247, 0.4658)
    mu = np.sort(np.abs(np.asarray(ss.multipliers)))
    assert np.allclose(mu, np.sort(np.abs(np.asarray(ref.multipliers))), rtol=1e-6)


def test_hill_stability_agrees_with_floquet_across_a_duffing_response():
    omegas = np.array([30.0, 40.0, 45.0, 50.0, 60.0])
    a = aj.frequency_response(duffing(), omegas, amplitude=F0, **TIGHT)
    b = aj.frequency_response(duffing(), omegas, amplitude=F0,
                              method=aj.HarmonicBalance(harmonics=9, tol=1e-12,
                                                        condense=False, stability="hill"))
    assert np.all(np.asarray(a.status) == 0) and np.all(np.asarray(b.status) == 0)
    # the same orbits (both from the linear response: the lower branch past the fold)
    assert np.allclose(np.asarray(b.amplitude), np.asarray(a.amplitude), rtol=1e-6)
    assert np.array_equal(np.asarray(b.stable), np.asarray(a.stable))
    mu_a = np.max(np.abs(np.asarray(a.multipliers)), axis=1)
    mu_b = np.max(np.abs(np.asarray(b.multipliers)), axis=1)
    assert np.allclose(mu_b, mu_a, rtol=1e-5)


def test_harmonic_balance_converges_algebraically_on_a_clearance_contact():
    # Kelvin-Voigt (non-adhesive): the contact force jumps where the damping term starts,
    # so the series converges slowly; measured errors 7.5e-5, 1.5e-5, 5.6e-6, 4.0e-6 at
    # H = 16, 32, 64, 128 (rate about H^-1.3)
    system = aj.ImpactAbsorber(M=1.0, k=1e3, c=0.5, m=0.2, gap=2e-3,
                               contact=aj.KelvinVoigt(stiffness=2e3, damping=2.0))
    forcing = aj.Harmonic(amplitude=3.0, omega=30.0)
    ref = aj.steady_state(system, forcing, **TIGHT)
    assert int(ref.status) == 0 and float(ref.impacts) > 0
    Hs = np.array([16, 32, 64, 128])
    errors = []
    for H in Hs:
        ss = aj.steady_state(system, forcing, guess=np.asarray(ref.state),
                             method=aj.HarmonicBalance(harmonics=int(H), samples=16 * int(H),
                                                       tol=1e-11))
        assert int(ss.status) == 0 and bool(ss.stable) == bool(ref.stable)
        errors.append(abs(float(ss.amplitude) / float(ref.amplitude) - 1))
    errors = np.array(errors)
    assert np.all(np.diff(errors) < 0)
    assert -3.0 < _fitted_rate(Hs, errors) < -0.8
    assert errors[-1] < 1e-5


def test_harmonic_balance_converges_algebraically_on_nlvib03s_unilateral_spring():
    """NLvib example 03 at Ω = 0.62 (one orbit, in contact twice a period): the balanced
    orbit's state at t = 0 against the exact piecewise-linear orbit (reference_nlvib03:
    exact flows, root-found switches), H = 8 … 64.  The spring's kink makes the
    convergence algebraic: measured 6.5e-2, 7.9e-3, 3.1e-3, 1.3e-3 (fitted H^-1.8; 3.0e-4 at
    H = 128)."""
    ref = ref03.periodic_orbit(0.62)
    assert ref["converged"] and ref["nswitch"] == 2
    x_ref = np.asarray(ref["x0"])
    system, forcing = nlvib03(), aj.Harmonic(amplitude=0.1, omega=0.62)
    Hs = np.array([8, 16, 32, 64])
    errors = []
    for H in Hs:
        ss = aj.steady_state(system, forcing, guess=x_ref,
                             method=aj.HarmonicBalance(harmonics=int(H), tol=1e-11,
                                                       condense=False))
        assert int(ss.status) == 0 and bool(ss.stable) == (ref["mu_max"] < 1)
        errors.append(np.max(np.abs(np.asarray(ss.state) - x_ref)) / np.max(np.abs(x_ref)))
    errors = np.array(errors)
    print("NLvib 03:", errors, f"rate {_fitted_rate(Hs, errors):.2f}")
    assert np.all(np.diff(errors) < 0)
    assert -3.0 < _fitted_rate(Hs, errors) < -0.8
    assert errors[-1] < 3e-3


def test_harmonic_balance_converges_algebraically_on_a_friction_absorber():
    """A friction absorber (m1 = 1 kg, k1 = 1e4 N/m, c1 = 2 N s/m; m2 = 0.2 kg, k2 = 1.5e3
    N/m; Coulomb μ = 0.3 at N = 2 N smoothed by tanh(v/1e-3)), 40 N at 90 rad/s, sticking
    and slipping: the balanced orbit's amplitude against shooting at rtol 1e-10, H = 8 …
    64.  Measured 7.2e-3, 3.5e-3, 2.4e-3, 1.1e-3 (fitted H^-0.85; 4.4e-4 at H = 128; with the
    smoother tanh(v/1e-2), 5.8e-5 at H = 64)."""
    system = aj.FrictionAbsorber(m1=1.0, k1=1e4, c1=2.0, m2=0.2, k2=1.5e3, c2=0.0,
                                 normal_force=2.0, friction=aj.Coulomb(mu=0.3, eps=1e-3))
    forcing = aj.Harmonic(amplitude=40.0, omega=90.0)
    ref = aj.steady_state(system, forcing, **TIGHT)
    assert int(ref.status) == 0
    Hs = np.array([8, 16, 32, 64])
    errors = []
    for H in Hs:
        ss = aj.steady_state(system, forcing, guess=np.asarray(ref.state),
                             method=aj.HarmonicBalance(harmonics=int(H), tol=1e-11))
        assert int(ss.status) == 0 and bool(ss.stable) == bool(ref.stable)
        errors.append(abs(float(ss.amplitude) / float(ref.amplitude) - 1))
    errors = np.array(errors)
    print("friction absorber:", errors, f"rate {_fitted_rate(Hs, errors):.2f}")
    assert np.all(np.diff(errors) < 0)
    assert -3.0 < _fitted_rate(Hs, errors) < -0.5
    assert errors[-1] < 2e-3


def test_bad_harmonic_balance_input_is_refused():
    with pytest.raises(ValueError, match="harmonics"):
        aj.HarmonicBalance(harmonics=0)
    with pytest.raises(ValueError, match="samples"):
        aj.HarmonicBalance(harmonics=10, samples=20)
    rigid = aj.ImpactAbsorber(M=1.0, k=1e3, c=0.5, m=0.2, gap=2e-3,
                              contact=aj.Restitution(0.6))
    with pytest.raises(ValueError, match="event-driven"):
        aj.steady_state(rigid, aj.Harmonic(amplitude=3.0, omega=30.0),
                        method=aj.HarmonicBalance())


def beam_with_friction_damper():
    """A cantilever beam (4 Hermite elements, 8 degrees of freedom) with a friction contact
    to ground at its tip (Coulomb smoothed at 10 mm/s), loaded at the tip."""
    beam = aj.cantilever_beam(4, length=1.0, EI=50.0, rho_A=1.0, rayleigh=(1.0, 1e-4))
    damper = aj.FrictionContact("w4", normal_force=2.0,
                                friction=aj.Coulomb(mu=0.3, eps=1e-2))
    return aj.StructuralSystem(beam, [damper], load="w4")


def test_condensed_and_full_balances_give_the_same_orbit_on_a_beam_with_a_friction_damper():
    # the condensed unknowns: the tip's 2H + 1 coefficients; the full: all 16 states'
    # (whose residual stalls near 1e-9: the beam's stiff modes condition it; the condensed
    # one reaches 1e-17)
    system = beam_with_friction_damper()
    forcing = aj.Harmonic(amplitude=2.0, omega=3.516 * np.sqrt(50.0))    # first mode
    full = aj.steady_state(system, forcing, method=aj.HarmonicBalance(
        harmonics=7, tol=1e-8, condense=False, stability="hill"))
    cond = aj.steady_state(system, forcing, method=aj.HarmonicBalance(harmonics=7, tol=1e-12))
    assert int(full.status) == 0 and int(cond.status) == 0
    size = np.max(np.abs(np.asarray(full.state)))
    assert np.max(np.abs(np.asarray(cond.state) - np.asarray(full.state))) < 1e-10 * size
    assert abs(float(cond.amplitude) / float(full.amplitude) - 1) < 1e-10
    # stable by Hill's method on the full balance and by the monodromy of the condensed
    # orbit: the same largest multiplier (0.87440 and 0.87442 at H = 7)
    assert bool(cond.stable) and bool(full.stable)
    mu_cond = np.max(np.abs(np.asarray(cond.multipliers)))
    mu_full = np.max(np.abs(np.asarray(full.multipliers)))
    assert abs(mu_cond - mu_full) < 1e-4


# NLvib example 08 (beam_tanhDryFriction): a steel cantilever, 2 m long, 0.1 m high in
# bending, 0.3 m thick (E = 185 GPa, ρ = 7830 kg/m³), 8 Hermite elements; tanh dry friction
# (1.5 N, eps = 6e-7 m/s) at the fourth node's deflection (the third free node, "w3"), 0.2 N
# at the tip, stiffness-proportional damping giving 1 % in the first mode with the contact
# held.  NLvib's harmonic balance (H = 7, N = 2^7, Ω stepped by 5 rad/s from 370 down)
# reports the tip's RMS peak 6.70985e-8 m at Ω = 195 rad/s.
NLVIB08_PEAK = 6.70985e-8


def nlvib08():
    EI, rho_A = 185e9 * 0.3 * 0.1**3 / 12, 7830 * 0.1 * 0.3
    M, K, names = aj.beam_matrices(8, length=2.0, EI=EI, rho_A=rho_A)
    held = [i for i in range(16) if names[i] != "w3"]
    Mh, Kh = M.toarray()[np.ix_(held, held)], K.toarray()[np.ix_(held, held)]
    omega_held = np.sqrt(np.min(np.linalg.eigvals(np.linalg.solve(Mh, Kh)).real))
    beam = aj.structure_from_matrices(M, K, rayleigh=(0.0, 2 * 0.01 / omega_held),
                                      dof_names=names)
    damper = aj.FrictionContact("w3", normal_force=1.5, friction=aj.Coulomb(mu=1.0, eps=6e-7))
    return aj.StructuralSystem(beam, [damper], load="w8", observe="w8"), omega_held


def test_the_friction_damped_beam_of_nlvib_example_08_peaks_where_nlvib_reports():
    system, omega_held = nlvib08()
    assert abs(omega_held - 248.97) < 0.01                  # NLvib's om_fixed(1)
    omegas = np.arange(185.0, 206.0, 5.0)
    fr = aj.frequency_response(system, omegas, amplitude=0.2, floquet=False,
                               method=aj.HarmonicBalance(harmonics=7, samples=128, tol=1e-10))
    assert np.all(np.asarray(fr.status) == 0)
    rms = np.asarray(fr.rms)
    assert omegas[np.argmax(rms)] == 195.0
    # the converged balance (H = 42; H = 84 differs by 3e-7): H = 7 is 6.5e-4 above it;
    # NLvib's figure lies 9e-5 below it and 7.7e-4 below our H = 7 (an independent numpy
    # balance of this model at H = 7, N = 128 gives our 6.715e-8)
    ref = aj.steady_state(system, aj.Harmonic(amplitude=0.2, omega=195.0), floquet=False,
                          method=aj.HarmonicBalance(harmonics=42, tol=1e-10))
    assert int(ref.status) == 0
    assert abs(rms[2] / float(ref.rms) - 1) < 1.5e-3
    assert abs(float(ref.rms) / NLVIB08_PEAK - 1) < 5e-4
    assert abs(rms[2] / NLVIB08_PEAK - 1) < 1.5e-3


def test_harmonic_balance_orbits_differentiate_implicitly_as_central_differences():
    # the full balance (Duffing, d amplitude / d k3) and the condensed one (the beam's
    # friction contact, d rms / d normal force and d rms / d mu): forward mode through the
    # implicit function theorem against central differences (measured 4e-11, 5e-13, 2e-12)
    def duffing_amplitude(k3):
        s = aj.replace_params(duffing(), {"cubic1.k3": k3})
        return aj.steady_state(s, aj.Harmonic(amplitude=F0, omega=45.0), floquet=False,
                               method=aj.HarmonicBalance(harmonics=9, tol=1e-12)).amplitude

    def beam_rms(p):
        s = aj.replace_params(beam_with_friction_damper(),
                              {"friction_contact1.normal_force": p[0],
                               "friction_contact1.mu": p[1]})
        forcing = aj.Harmonic(amplitude=2.0, omega=3.516 * np.sqrt(50.0))
        return aj.steady_state(s, forcing, floquet=False,
                               method=aj.HarmonicBalance(harmonics=7, tol=1e-12)).rms

    g = float(jax.jacfwd(duffing_amplitude)(1e6))
    fd = float(duffing_amplitude(1e6 + 1e2) - duffing_amplitude(1e6 - 1e2)) / 2e2
    assert abs(g / fd - 1) < 1e-6
    p = jnp.array([2.0, 0.3])
    g = np.asarray(jax.jacfwd(beam_rms)(p))
    for i, h in enumerate((1e-4, 1e-5)):
        e = jnp.zeros(2).at[i].set(h)
        fd = float(beam_rms(p + e) - beam_rms(p - e)) / (2 * h)
        assert abs(g[i] / fd - 1) < 1e-6
