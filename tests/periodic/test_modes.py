"""Nonlinear modes (``aj.nonlinear_modes``, extended periodic motion concept by harmonic
balance): exact on a linear structure (undamped frequencies, modal damping ratios), and on
NLvib example 05 (2-DOF, tanh dry friction) converging to the damped nonlinear mode
computed by an independent scipy shooting (``reference_epmc``) as the harmonics grow."""

import numpy as np
import pytest
import reference_epmc as ref

import absorber_jax as aj


def nlvib05():
    structure = aj.structure_from_matrices(np.diag(np.diag(ref.M)), ref.K,
                                           dof_names=["x1", "x2"])
    friction = aj.FrictionContact("x1", normal_force=ref.MU_N,
                                  friction=aj.Coulomb(mu=1.0, eps=ref.EPS))
    return aj.StructuralSystem(structure, [friction], load="x2")


def test_the_modes_of_a_linear_structure_are_its_natural_frequencies_and_damping_ratios():
    zeta = [0.01, 0.03, 0.02]
    building = aj.shear_building([1.0, 1.0, 1.0], [1e3, 1e3, 1e3], modal_damping=zeta)
    system = aj.StructuralSystem(building, [], load="floor1")
    omega = np.asarray(building.natural_frequencies())
    for mode in (1, 2, 3):
        nm = aj.nonlinear_modes(system, [0.01, 0.1], mode=mode,
                                method=aj.HarmonicBalance(harmonics=3, tol=1e-12))
        assert np.all(nm.ok)
        np.testing.assert_allclose(nm.omega, omega[mode - 1], rtol=1e-10)
        np.testing.assert_allclose(nm.damping_ratio, zeta[mode - 1], rtol=1e-8)
        # a linear mode q = a φ cos ωt with φᵀMφ = 1: the floors move a |φ|
        _, psi = np.linalg.eigh(np.asarray(building.stiffness))
        phi = np.abs(psi[:, mode - 1])
        np.testing.assert_allclose(nm.dof_amplitude, np.outer(nm.amplitude, phi), rtol=1e-8)
        np.testing.assert_allclose(nm.dof_harmonic, nm.dof_amplitude, rtol=1e-10)


def test_the_friction_damped_mode_of_nlvib_example_05_converges_to_shooting(tmp_path):
    system = nlvib05()
    a = np.logspace(-1.5, 1.0, 40)
    fine = aj.nonlinear_modes(system, a, method=aj.HarmonicBalance(harmonics=40, tol=1e-11))
    assert np.all(fine.ok)
    # the limits: stuck at small amplitude (the mode with x1 held, sqrt(640) rad/s, damped
    # only by the tanh's viscous slope), sliding at large (the free chain's 24.156 rad/s)
    assert abs(fine.omega[0] / np.sqrt(640.0) - 1) < 1e-4
    free = np.sqrt(np.linalg.eigvals(np.linalg.solve(ref.M, ref.K)).real.min())
    assert abs(fine.omega[-1] / free - 1) < 2e-3
    # damping peaks in the transition (3.8 % near a = 0.17) and falls on either side
    peak = int(np.argmax(fine.damping_ratio))
    assert 0.03 < fine.damping_ratio[peak] < 0.05 and 0.1 < a[peak] < 0.3
    assert fine.damping_ratio[0] < 0.002 and fine.damping_ratio[-1] < 0.002
    # against the shooting reference in the transition, where the harmonics matter most
    # (measured at H = 5 and 40: ω 4.0e-3 → 3.2e-5 and ζ 0.11 → 4.0e-4 at a = 0.166;
    # ω 3.0e-3 → 1.3e-4 and ζ 2.6e-2 → 6.8e-4 at a = 0.3)
    pts = (0.166, 0.3)
    nm_pts = {H: aj.nonlinear_modes(system, pts, method=aj.HarmonicBalance(harmonics=H,
                                                                           tol=1e-11))
              for H in (5, 40)}
    for i, ai in enumerate(pts):
        m = nm_pts[40]
        c = m.coefficients[i]
        k = np.arange(1, 41)[:, None]
        q0, v0 = c[0] + c[1::2].sum(0), m.omega[i] * (k * c[2::2]).sum(0)
        w, zeta, _ = ref.damped_mode(ai, [q0[0], q0[1], v0[0], m.omega[i],
                                          2 * m.omega[i] * m.damping_ratio[i]])
        err = {H: (abs(nm_pts[H].omega[i] / w - 1), abs(nm_pts[H].damping_ratio[i] / zeta - 1))
               for H in nm_pts}
        assert err[40][0] < 3e-4 and err[40][1] < 2e-3, err
        assert err[40][0] < 0.1 * err[5][0] and err[40][1] < 0.1 * err[5][1], err
    fine.to_csv(tmp_path / "backbone.csv")
    head = (tmp_path / "backbone.csv").read_text().splitlines()[0]
    assert head.startswith("amplitude [kg^0.5 m],omega [rad/s],damping_ratio [-]")


def test_bad_nonlinear_mode_input_is_refused():
    system = nlvib05()
    with pytest.raises(ValueError, match="amplitudes must be positive"):
        aj.nonlinear_modes(system, [0.1, 0.05])
    with pytest.raises(ValueError, match=r"mode must be in \[1, 1\]"):
        aj.nonlinear_modes(system, [0.1], mode=2)
    with pytest.raises(ValueError, match="method must be a HarmonicBalance"):
        aj.nonlinear_modes(system, [0.1], method=aj.Shooting())
    absorber, _ = aj.presets.impact("kelvin_voigt", omega=30.0)
    with pytest.raises(ValueError, match="StructuralSystem whose elements keep no states"):
        aj.nonlinear_modes(absorber, [0.1])
