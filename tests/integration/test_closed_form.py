"""Closed-form flights of rigid-impact systems (``_integration.flights``): the affine modes
against the systems' own rates, whole runs against the event-exact reference of
tests/reference_impacts.py (to rounding, where diffrax gets its tolerance), an excursion
through a wall between two nodes, and derivatives against central differences."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from reference_impacts import RigidImpactAbsorber, RigidStopOscillator

import absorber_jax as aj
from absorber_jax._integration.flights import augmented_state, in_closed_form, mode_matrix

SCENE = dict(M=1.0, k=1e3, c=0.5, m=0.2, gap=2e-3)


def _absorber(e=0.6):
    return aj.ImpactAbsorber(**SCENE, contact=aj.Restitution(e))


def _building():
    st = aj.shear_building([1000.0] * 3, [1e6] * 3, modal_damping=0.02)
    ball = aj.ImpactDamper("floor3", m=50.0, gap=0.01, contact=aj.Restitution(0.7))
    return aj.StructuralSystem(st, [ball], load="floor3")


def _building_with_tmd(e=0.7):
    # a tuned mass damper on the first floor beside the rigid ball on the top one: linear,
    # so the modes stay affine
    st = aj.shear_building([1000.0] * 3, [1e6] * 3, modal_damping=0.02)
    ball = aj.ImpactDamper("floor3", m=50.0, gap=0.01, contact=aj.Restitution(e))
    tmd = aj.TunedMassDamper("floor1", m=40.0, k=7.5e3, c=90.0)
    return aj.StructuralSystem(st, [ball, tmd], load="floor3")


def test_affine_modes_reproduce_every_modes_rate():
    rng = np.random.default_rng(0)
    forcings = [aj.Harmonic(amplitude=3.0, omega=30.0),
                aj.MultiHarmonic([2.0, 0.7, 0.3], 25.0, phases=[0.1, 1.0, -0.4],
                                 orders=[0, 1, 3])]
    cases = [(_absorber(), [0, 1, -1]),
             (_building(), [np.array([0]), np.array([1]), np.array([-1])]),
             (_building_with_tmd(), [np.array([0]), np.array([1]), np.array([-1])])]
    # compiled once per system (op by op, every operation would compile on its own)
    matrix, augmented = eqx.filter_jit(mode_matrix), eqx.filter_jit(augmented_state)
    rate = eqx.filter_jit(lambda system, *args: system.mode_rate(*args))
    for system, modes in cases:
        assert system.affine_modes and system.hybrid
        for forcing in forcings:
            assert in_closed_form(system, forcing)
            nat = system.state_scale(forcing)
            for mode in modes:
                A = matrix(system, forcing, jnp.asarray(mode), nat, 0.0)
                for _ in range(3):
                    t = jnp.asarray(rng.uniform(0, 1))
                    s = jnp.asarray(rng.normal(size=nat.shape)) * nat
                    z = augmented(s / nat, forcing, t)
                    want = rate(system, t, s, forcing, jnp.asarray(mode))
                    got = (A @ z)[: nat.shape[0]] * nat
                    np.testing.assert_allclose(got, want, rtol=1e-12,
                                               atol=1e-12 * float(jnp.max(jnp.abs(want))))
    # sampled forcings and systems with friction keep the general integrator
    assert not in_closed_form(_absorber(), aj.PeriodicForcing(lambda t: jnp.sin(30 * t), 30.0))
    fa = aj.FrictionAbsorber(m1=1.0, k1=1e4, c1=2.0, m2=0.2, k2=1.8e3, c2=0.0,
                             normal_force=2.0, friction=aj.Coulomb(mu=0.3))
    assert fa.hybrid and not fa.affine_modes
    # a nonlinear element beside a rigid one keeps the general integrator
    st = aj.shear_building([1000.0] * 3, [1e6] * 3, modal_damping=0.02)
    ball = aj.ImpactDamper("floor3", m=50.0, gap=0.01, contact=aj.Restitution(0.7))
    rubbing = aj.FrictionDamper("floor1", m=40.0, k=7.5e3, c=0.0, normal_force=50.0,
                                friction=aj.Coulomb(mu=0.3, eps=1e-3))
    mixed = aj.StructuralSystem(st, [ball, rubbing], load="floor3")
    assert mixed.hybrid and not mixed.affine_modes


def test_a_tuned_mass_damper_beside_a_rigid_ball_flies_in_closed_form():
    # closed-form flights of the building with a TMD and a rigid ball: diffrax's flights
    # (solver named) converge to them as their tolerance tightens and their order rises,
    # through many impacts
    system = _building_with_tmd()
    f = aj.Harmonic(amplitude=2000.0, omega=14.0)
    ts = np.linspace(0.0, 4.0, 401)
    runs = {}
    for solver, tol in ((None, 1e-9), ("tsit5", 1e-8), ("dopri8", 1e-12)):
        tr = aj.simulate(system, f, 4.0, ts=ts,
                         integrator=aj.Integrator(solver=solver, rtol=tol, atol=tol * 1e-3))
        assert int(tr.status) == 0
        runs[solver, tol] = np.asarray(tr.ys)
        if solver is None:
            assert tr.solver == "closed-form"
    exact = runs[None, 1e-9]
    stroke = exact[:, system.slice_of("impact1")][:, 1]       # the ball's relative velocity
    assert np.sum(np.abs(np.diff(np.sign(stroke))) > 0) >= 8    # reversed many times
    scale = np.max(np.abs(exact), axis=0)
    err = {key: np.max(np.abs(run - exact) / scale) for key, run in runs.items()}
    # measured: 5.7e-6 (tsit5, 1e-8) and 1.4e-9 (dopri8, 1e-12)
    assert err["dopri8", 1e-12] < 2e-8 and err["dopri8", 1e-12] < 0.01 * err["tsit5", 1e-8], err


def test_runs_match_the_event_exact_reference_to_rounding():
    # a run through impacts and sticking (the hard scene's chatter): closed form against the
    # reference's closed-form flights to rounding; diffrax (solver named) to its tolerance
    ref_sys = RigidImpactAbsorber(*SCENE.values(), 0.6, 3.0, 30.0)
    ts = np.linspace(0.0, 1.0, 1001)
    ref, events = ref_sys.run([0, 0, 0, 0], 0.0, 1.0, ts)
    assert sum(k == "impact" for _, k in events) > 50
    scale = np.max(np.abs(ref[:, 0]))
    errs = {}
    for solver in (None, "tsit5"):
        tr = aj.simulate(_absorber(), aj.Harmonic(amplitude=3.0, omega=30.0), 1.0, ts=ts,
                         integrator=aj.Integrator(solver=solver, rtol=1e-9, atol=1e-11))
        assert int(tr.status) == 0
        errs[solver] = max(np.max(np.abs(np.asarray(tr.x1) - ref[:, 0])),
                           np.max(np.abs(np.asarray(tr.x2) - ref[:, 2]))) / scale
    assert tr.solver == "tsit5"
    assert errs[None] < 1e-10 and errs[None] < errs["tsit5"], errs


def test_an_excursion_through_the_wall_between_two_nodes_is_caught():
    # x'' + 0.1 x' + x = A sin(t + φ), stop at x = 1: the linear response -10 A cos(t + φ)
    # overshoots the stop by 1e-6 of it for 2.8e-3 s around t = π - φ, midway between two
    # nodes (2π/256 apart): the flight's apex between them is checked on the exact flow
    A, phi = 0.1 * (1 + 1e-6), np.pi / 256
    st = aj.structure_from_matrices([[1.0]], [[1.0]], damping=[[0.1]], dof_names=["x"])
    system = aj.StructuralSystem(st, [aj.Contact("x", gap=1.0, contact=aj.Restitution(0.8))],
                                 load="x")
    forcing = aj.Harmonic(amplitude=A, omega=1.0).at_phase(phi)
    y0 = [-10 * A * np.cos(phi), 10 * A * np.sin(phi)]
    T = 2 * np.pi
    tr = aj.simulate(system, forcing, T, y0=y0, ts=np.array([0.0, T]))
    # the reference: the same oscillator seen from time φ (its forcing is A sin(W t))
    ref, events = RigidStopOscillator(1.0, 0.1, 1.0, 1.0, 0.8, A, 1.0).run(
        y0, phi, phi + T, np.array([phi + T]))
    assert sum(k == "impact" for _, k in events) == 1
    end = np.asarray(tr.ys)[-1]
    np.testing.assert_allclose(end, ref[-1], atol=1e-9)
    # without the impact the motion would have stayed on the linear response
    assert np.max(np.abs(ref[-1] - np.asarray(y0))) > 1e-4


def test_period_map_derivatives_match_central_differences():
    from absorber_jax._integration.flow import integrate_flow, make_config, state_scale

    system = _absorber(0.7)
    x0 = jnp.array([-1.5e-4, 0.125, -3.9e-4, 0.124])
    sc = state_scale(system, aj.Harmonic(amplitude=3.0, omega=24.0))   # one fixed scale

    def end(p):
        w, gap, e = p
        f = aj.Harmonic(amplitude=3.0, omega=w)
        s = aj.ImpactAbsorber(M=1.0, k=1e3, c=0.5, m=0.2, gap=gap, contact=aj.Restitution(e))
        ys, _ = integrate_flow((s, f), s.to_internal(x0) / sc, f.period, None,
                               cfg=make_config(s, f))
        return ys[-1] * sc

    p = jnp.array([24.0, 2e-3, 0.7])
    J = jax.jit(jax.jacfwd(end))(p)
    end = jax.jit(end)              # one compiled program for the six differences
    for i, h in enumerate((1e-6, 1e-10, 1e-7)):
        dp = jnp.zeros(3).at[i].set(h)
        fd = (end(p + dp) - end(p - dp)) / (2 * h)
        np.testing.assert_allclose(J[:, i], fd, rtol=1e-5, atol=1e-6 * float(jnp.max(jnp.abs(fd))))


def test_batched_exponential_and_its_frechet_derivative_match_scipy():
    # scipy's Padé exponential and Fréchet derivative (Al-Mohy and Higham) as the
    # independent reference, on a batch spanning norms 0 to 300 (0 to 11 squarings)
    from scipy.linalg import expm as sp_expm
    from scipy.linalg import expm_frechet

    from absorber_jax._integration.flights import expm

    rng = np.random.default_rng(3)
    norms = [0.0, 1e-3, 0.2, 1.0, 7.0, 40.0, 300.0]
    B = np.stack([rng.normal(size=(7, 7)) * s / 7 for s in norms], axis=-1)
    dB = rng.normal(size=B.shape)
    E, L = jax.jvp(expm, (jnp.asarray(B),), (jnp.asarray(dB),))
    for j in range(len(norms)):
        E_ref, L_ref = expm_frechet(B[..., j], dB[..., j])
        np.testing.assert_allclose(np.asarray(E[..., j]), sp_expm(B[..., j]), rtol=0,
                                   atol=1e-12 * np.max(np.abs(E_ref)))
        np.testing.assert_allclose(np.asarray(L[..., j]), L_ref, rtol=0,
                                   atol=1e-11 * np.max(np.abs(L_ref)))
    # a non-finite matrix gives a non-finite exponential (no endless squaring)
    bad = np.stack([B[..., 3], np.full((7, 7), np.inf), np.full((7, 7), np.nan)], axis=-1)
    E = np.asarray(expm(jnp.asarray(bad)))
    assert np.all(np.isfinite(E[..., 0])) and not np.any(np.isfinite(E[..., 1:]))


def test_jacobian_through_sticking_and_chatter_matches_central_differences():
    # a period of the orbit that chatters and sticks (e = 0.6 at 30 rad/s, held against a
    # wall part of the period): the Jacobian in the state and the frequency (both through
    # the integration, the frequency's by flights._frequency_jvp), against central
    # differences
    from absorber_jax._integration.flow import (
        event_counts,
        integrate_flow,
        make_config,
        state_scale,
    )

    system = _absorber(0.6)
    f0 = aj.Harmonic(amplitude=3.0, omega=30.0)
    ss = aj.steady_state(system, f0)
    sc = state_scale(system, f0)
    x = system.to_internal(jnp.asarray(ss.state)) / sc
    cfg = make_config(system, f0)
    impacts, held = event_counts((system, f0), x, f0.period, cfg)
    assert int(impacts) >= 20 and float(held) > 0.1 * float(f0.period)

    @jax.jit
    def end(u):
        f = aj.Harmonic(amplitude=3.0, omega=u[-1])
        ys, _ = integrate_flow((system, f), u[:-1], f.period, None, cfg=cfg)
        return ys[-1]

    u = jnp.append(x, 30.0)
    J = np.asarray(jax.jacfwd(end)(u))
    for i, h in enumerate((1e-7,) * 4 + (1e-7 * 30.0,)):
        du = jnp.zeros(5).at[i].set(h)
        fd = np.asarray(end(u + du) - end(u - du)) / (2 * h)
        np.testing.assert_allclose(J[:, i], fd, rtol=0, atol=1e-6 * max(1.0, np.max(np.abs(fd))))


def test_frequency_jvp_of_one_flight_matches_the_frechet_derivative():
    # exact_flight's JVP with the frequency moving (flights._frequency_jvp: Van Loan's
    # block exponential) against the JVP through the exponential's Fréchet derivative
    # (flights._exact_flight), with tangents in the state, the times, the scale and ω at
    # once, orders 0, 1 and 3; and with the scale's tangent alone
    from absorber_jax._integration import flights

    system = _absorber(0.7)
    f = aj.MultiHarmonic([3.0, 1.0, 0.5], omega=28.0, orders=(0, 1, 3), phases=(0.2, 0.0, 0.4))
    scale = system.state_scale(f) * jnp.array([1.3, 0.7, 2.0, 0.9])
    x, t, tau = jnp.array([0.3, -0.8, 0.1, 0.5]), jnp.asarray(0.011), jnp.asarray(0.037)
    mode = jnp.asarray(0)
    rng = np.random.default_rng(5)
    d_scale = jnp.asarray(rng.normal(size=4)) * scale * 1e-2
    no_force = jax.tree_util.tree_map(lambda _: None, f)
    for d_omega in (jnp.asarray(0.7), None):
        t_forc = eqx.tree_at(lambda g: g.omega, no_force, d_omega,
                             is_leaf=lambda a: a is None)
        moving = d_omega is not None
        tangents = (jax.tree_util.tree_map(lambda _: None, system), t_forc, None, d_scale,
                    jnp.asarray(rng.normal(size=4)) if moving else None,
                    jnp.asarray(0.3) if moving else None, jnp.asarray(-0.2) if moving else None)
        primals = (system, f, mode, scale, x, t, tau)
        _, dy = eqx.filter_jit(flights._frequency_jvp)(primals, tangents)
        _, ref = eqx.filter_jit(eqx.filter_jvp)(flights._exact_flight, primals, tangents)
        np.testing.assert_allclose(np.asarray(dy), np.asarray(ref), rtol=0,
                                   atol=1e-12 * float(jnp.max(jnp.abs(ref))))


def test_frequency_column_by_van_loan_matches_the_frechet_replay(monkeypatch):
    # the period map's derivative in the forcing frequency alone goes through the
    # integration (flights._frequency_jvp: one exponential of 2J more rows a flight);
    # together with the amplitude it goes through the replay of the recorded flights
    # (the exponential's Fréchet derivative, the saltations composed again): two
    # derivations of one column on an impacting period under two harmonics (the column
    # against central differences: test_jacobian_through_sticking_and_chatter_...)
    from absorber_jax._integration.flights import frequency_in_rotation_only
    from absorber_jax._integration.flow import integrate_flow, make_config, state_scale

    system = _absorber(0.7)
    f0 = aj.MultiHarmonic([3.0, 1.0], omega=28.0, orders=(1, 3), phases=(0.0, 0.4))
    assert frequency_in_rotation_only(system, f0)
    assert frequency_in_rotation_only(_building_with_tmd(), f0)   # modes as vectors
    sc = state_scale(system, f0)
    cfg = make_config(system, f0)
    x = jnp.asarray(system.linear_guess(f0)) / sc       # a period with 8 impacts from it

    def end(w, a):
        f = aj.MultiHarmonic(jnp.stack([a, 1.0]), omega=w, orders=(1, 3), phases=(0.0, 0.4))
        ys, _ = integrate_flow((system, f), x, f.period, None, cfg=cfg)
        return ys[-1]

    from absorber_jax._integration import flights

    traced = []
    real = flights._frequency_jvp
    monkeypatch.setattr(flights, "_frequency_jvp", lambda *a: traced.append(1) or real(*a))
    w, a = jnp.asarray(28.0), jnp.asarray(3.0)
    forward = np.asarray(jax.jit(jax.jacfwd(end))(w, a))
    assert traced                        # the frequency went through the integration
    traced.clear()
    replayed = np.asarray(jax.jit(jax.jacfwd(end, argnums=(0, 1)))(w, a)[0])
    assert not traced                    # and here through the replay
    # measured: 4e-16 of the column's size between the two
    np.testing.assert_allclose(forward, replayed, rtol=0, atol=1e-10 * np.max(np.abs(forward)))
    assert np.max(np.abs(forward)) > 0.1
    # a forcing whose coefficients move with the frequency keeps the replay
    assert not frequency_in_rotation_only(system, _Unbalance(3.0, 28.0))


class _Unbalance(aj.AbstractPeriodicForcing):
    """A rotating unbalance ``a ω² sin(ωt)`` [N]: its coefficient moves with ``ω``."""

    amplitude: float
    omega: float

    def __call__(self, t):
        return self.amplitude * self.omega**2 * jnp.sin(self.omega * t)

    def with_omega(self, omega):
        return _Unbalance(self.amplitude, omega)

    def with_amplitude(self, amplitude):
        return _Unbalance(amplitude, self.omega)

    def at_phase(self, phase):
        raise NotImplementedError

    @property
    def harmonics_exact(self):
        return True

    def harmonics(self):
        c = self.amplitude * self.omega**2
        return np.array([1]), jnp.reshape(jnp.asarray(c, dtype=float), (1,)).astype(complex)
