"""The extension points, used from the public API alone: forcings beyond one harmonic
(MultiHarmonic, PeriodicForcing), support (base) excitation, and a user-written element and
contact law.  Each is checked against an independent reference: a hand-written ODE
integrated by scipy, closed-form frequency response functions, or an equivalent model built
another way."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from builders import CubicSpring  # a user-written element, shared with other tests
from scipy.integrate import solve_ivp

import absorber_jax as aj


# --------------------------------------------------------------------- user-written pieces
class CubicWall(aj.AbstractCompliantLaw):
    """``f(δ, δ̇) = k δ³ + c δ̇`` (a user-written contact law)."""

    exponent = 3.0
    damping_unit = "N s/m"
    stiffness: float
    damping: float
    eps: float
    adhesive: bool = eqx.field(static=True)

    def elastic_force(self, delta):
        return self.stiffness * delta**3

    def viscous_force(self, delta, delta_dot):
        return self.damping * delta_dot

    def potential(self, delta):
        return 0.25 * self.stiffness * delta**4


def _softplus(x):
    return np.logaddexp(0.0, x)


def _sigmoid(x):
    return 0.5 * (1.0 + np.tanh(0.5 * x))


def _max_error(a, b):
    """Largest difference relative to the reference's largest magnitude."""
    a, b = np.asarray(a), np.asarray(b)
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


# ------------------------------------------------------------------------- a cubic spring
MASSES2, STOREYS2, RAYLEIGH2 = [1.0, 0.8], [400.0, 300.0], (0.2, 1e-4)
K3_GROUND, K3_BETWEEN = 2e6, 8e5


def _cubic_building():
    b = aj.shear_building(MASSES2, STOREYS2, rayleigh=RAYLEIGH2)
    els = [CubicSpring("floor1", k3=K3_GROUND),
           CubicSpring("floor2", k3=K3_BETWEEN, other="floor1", name="link")]
    return aj.StructuralSystem(b, els, load="floor2"), b


def test_cubic_spring_element_simulates_like_the_hand_written_ode():
    sysm, b = _cubic_building()
    assert sysm.element_names == ("cubic1", "link")
    assert sysm.parameter_names() == ["cubic1.k3", "link.k3"]
    forcing = aj.MultiHarmonic([3.0, 1.0], omega=14.0, orders=(1, 2), phases=(0.0, 0.5))
    ts = np.linspace(0.0, 2.0, 401)
    tr = aj.simulate(sysm, forcing, 2.0, ts=ts, rtol=1e-11, atol=1e-13, energy=True)

    M, C, K = (np.asarray(a) for a in (b.mass, b.damping, b.stiffness))

    def rhs(t, y):
        x, v = y[:2], y[2:]
        f = 3.0 * np.sin(14.0 * t) + np.sin(28.0 * t + 0.5)
        g, d = K3_GROUND * x[0] ** 3, K3_BETWEEN * (x[1] - x[0]) ** 3
        fnl = np.array([g - d, d])
        a = np.linalg.solve(M, np.array([0.0, f]) - C @ v - K @ x - fnl)
        return np.concatenate([v, a])

    ref = solve_ivp(rhs, (0.0, 2.0), np.zeros(4), t_eval=ts, method="DOP853", rtol=1e-12,
                    atol=1e-14)
    err = _max_error(tr.ys, ref.y.T)
    assert err < 1e-8, err            # measured 2.1e-11
    # the element's energy closes the balance: E(t) - E(0) = work - dissipated
    E = np.asarray(tr.mechanical_energy())
    balance = E - E[0] - (np.asarray(tr.work) - np.asarray(tr.dissipated))
    assert np.max(np.abs(balance)) < 1e-7 * np.max(np.asarray(tr.work)), balance  # 1.8e-11


# -------------------------------------------------------------- forcing beyond one harmonic
MASSES3, STOREYS3, RAYLEIGH3 = [1.0, 1.2, 0.8], [800.0, 700.0, 500.0], (0.3, 2e-4)
LOAD3 = {"floor1": 1.0, "floor3": 0.5}
AMPS, ORDERS, PHASES = [1.5, 0.6, 0.3], (1, 2, 5), [0.2, -0.5, 1.1]


def _linear_building():
    b = aj.shear_building(MASSES3, STOREYS3, rayleigh=RAYLEIGH3)
    return aj.StructuralSystem(b, load=LOAD3, observe="floor3"), b


def _superposed(b, omega, ts=(0.0,)):
    """Closed-form periodic response (displacements, velocities) at ``ts``: the harmonics'
    complex responses through the receptance, superposed."""
    load = np.array([LOAD3.get(d, 0.0) for d in b.dof_names])
    ts = np.asarray(ts)
    x = np.zeros((ts.size, 3))
    v = np.zeros((ts.size, 3))
    for A, k, phi in zip(AMPS, ORDERS, PHASES):
        X = np.asarray(b.receptance(k * omega)) @ load * A * np.exp(1j * phi)
        e = np.exp(1j * k * omega * ts)[:, None]
        x += np.imag(X[None, :] * e)
        v += np.imag(1j * k * omega * X[None, :] * e)
    return x, v


def test_multiharmonic_steady_state_of_a_linear_building_is_the_superposed_frf():
    sysm, b = _linear_building()
    omega = 7.0
    forcing = aj.MultiHarmonic(AMPS, omega=omega, orders=ORDERS, phases=PHASES)
    ss = aj.steady_state(sysm, forcing)
    assert int(ss.status) == 0 and bool(ss.stable)
    x0, v0 = _superposed(b, omega)
    err = _max_error(ss.state, np.concatenate([x0[0], v0[0]]))
    assert err < 1e-8, err            # measured 2.7e-16
    # the orbit over a period, integrated from the steady state, is the closed form too
    T = 2 * np.pi / omega
    ts = np.linspace(0.0, T, 257)
    tr = aj.simulate(sysm, forcing, T, ts=ts, y0=ss.state, rtol=1e-11, atol=1e-13)
    x, _ = _superposed(b, omega, ts)
    err = _max_error(tr.ys[:, :3], x)
    assert err < 1e-8, err            # measured 2.8e-12
    # the amplitudes: half peak-to-peak of the observable, and its fundamental component
    dense, _ = _superposed(b, omega, np.linspace(0.0, T, 20001))
    half_p2p = 0.5 * (dense.max(0) - dense.min(0))
    # (sampled, refined by parabolas: measured 1.6e-6 with the 5th harmonic in the signal)
    np.testing.assert_allclose(ss.dof_amplitude[:3], half_p2p, rtol=1e-5)
    H1 = np.asarray(b.receptance(omega)) @ np.array([1.0, 0.0, 0.5]) * AMPS[0]
    np.testing.assert_allclose(float(ss.harmonic), abs(H1[2]), rtol=1e-6)   # 4.4e-13
    # the same signal as a PeriodicForcing: the same orbit
    k, a, p = (jnp.asarray(u, dtype=float) for u in (ORDERS, AMPS, PHASES))
    pf = aj.PeriodicForcing(lambda t: jnp.sum(a * jnp.sin(k * omega * t + p)), omega)
    ss2 = aj.steady_state(sysm, pf)
    assert int(ss2.status) == 0
    err = _max_error(ss2.state, ss.state)
    assert err < 1e-8, err            # measured 3.2e-16


def test_frequency_response_sweeps_the_fundamental_of_a_multiharmonic_forcing():
    sysm, b = _linear_building()
    omegas = np.array([5.0, 9.0, 13.0])
    shape = aj.MultiHarmonic(AMPS, omega=1.0, orders=ORDERS, phases=PHASES)
    fr = aj.frequency_response(sysm, omegas, amplitude=shape)
    assert fr.ok.all()
    for i, w in enumerate(omegas):
        x0, v0 = _superposed(b, w)
        err = _max_error(fr.states[i], np.concatenate([x0[0], v0[0]]))
        assert err < 1e-8, (w, err)   # measured <= 1.8e-14


def test_periodic_forcing_reproduces_harmonic():
    b = aj.shear_building([1.0, 0.5], [500.0, 200.0], rayleigh=(0.1, 1e-4))
    sysm = aj.StructuralSystem(b, [aj.TunedMassDamper("floor2", m=0.05, k=20.0, c=0.2)],
                               load="floor1", observe="floor2")
    h = aj.Harmonic(amplitude=2.0, omega=18.0)
    pf = aj.PeriodicForcing(lambda t: 2.0 * jnp.sin(18.0 * t), 18.0)
    ts = np.linspace(0.0, 1.5, 301)
    np.testing.assert_array_equal(np.asarray(jax.vmap(pf)(ts)), np.asarray(jax.vmap(h)(ts)))
    # at another fundamental: the same waveform, time rescaled
    np.testing.assert_allclose(np.asarray(jax.vmap(pf.with_omega(25.0))(ts)),
                               np.asarray(jax.vmap(h.with_omega(25.0))(ts)), rtol=0,
                               atol=1e-13)
    assert float(pf.amplitude) == pytest.approx(2.0, rel=1e-3)
    a = aj.simulate(sysm, h, 1.5, ts=ts)
    p = aj.simulate(sysm, pf, 1.5, ts=ts)
    err = _max_error(p.ys, a.ys)
    assert err < 1e-12, err           # measured 0


# ------------------------------------------------------------------------ base excitation
def test_base_excitation_is_the_inertia_load_of_the_structure():
    """A building with massless nonlinear elements: BaseExcitation and the explicit load
    ``-M r a_g`` (r = 1) are the same equations; the modal model with the participation
    factors gives the same motion too."""
    b = aj.shear_building(MASSES3, STOREYS3, rayleigh=RAYLEIGH3)
    els = [CubicSpring("floor3", k3=3e5, other="floor2"),
           aj.Contact("floor1", gap=4e-3, contact=aj.KelvinVoigt(stiffness=2e4, damping=5.0,
                                                                  adhesive=True))]
    ag = aj.MultiHarmonic([2.0, 0.8], omega=9.0, orders=(1, 3))
    ts = np.linspace(0.0, 1.5, 301)
    based = aj.StructuralSystem(b, els, load=aj.BaseExcitation(), observe="floor3")
    explicit = aj.StructuralSystem(b, els, load=-(np.asarray(b.mass) @ np.ones(3)),
                                   observe="floor3")
    tb = aj.simulate(based, ag, 1.5, ts=ts, rtol=1e-10, atol=1e-12)
    te = aj.simulate(explicit, ag, 1.5, ts=ts, rtol=1e-10, atol=1e-12)
    err = _max_error(tb.ys, te.ys)
    assert err < 1e-10, err           # measured 0
    assert np.max(np.abs(np.asarray(tb.ys[:, :3]))) > 4e-3        # the contact closes
    # the modal model of all three modes, observed at every floor
    modal = b.modal()
    mb = aj.StructuralSystem(modal, els, observe="floor3", load=aj.BaseExcitation(
        participation=b.modal_participation()))
    tm = aj.simulate(mb, ag, 1.5, ts=ts, rtol=1e-10, atol=1e-12)
    got = np.stack([np.asarray(tm.dof(d)) for d in b.dof_names], axis=1)
    err = _max_error(got, np.asarray(tb.ys[:, :3]))
    assert err < 1e-7, err            # measured 1.6e-10


def test_base_excitation_loads_an_absorbers_own_mass():
    """TMDs as elements under BaseExcitation against the TMDs as coordinates of the
    structure (with_tuned_mass_dampers) under the explicit load -M r a_g with r = 1 on every
    mass, the TMDs' included; and the energy balance of the inertia loads."""
    b = aj.shear_building([1.0, 0.7], [600.0, 400.0], rayleigh=(0.1, 1e-4))
    tmd = ("floor2", 0.06, 12.0, 0.15)
    based = aj.StructuralSystem(b, [aj.TunedMassDamper(tmd[0], m=tmd[1], k=tmd[2], c=tmd[3])],
                                load=aj.BaseExcitation(), observe="floor2")
    aug = b.with_tuned_mass_dampers([tmd])
    coords = aj.StructuralSystem(aug, load=-(np.asarray(aug.mass) @ np.ones(3)),
                                 observe="floor2")
    ag = aj.Harmonic(amplitude=1.5, omega=14.0)
    sb, sc = aj.steady_state(based, ag), aj.steady_state(coords, ag)
    assert int(sb.status) == 0 and int(sc.status) == 0
    # (floor1, floor2, tmd) displacements and velocities, relative to the support
    got = np.asarray(sb.state)
    tmd_x, tmd_v = got[1] + got[4], got[3] + got[5]
    mine = np.array([got[0], got[1], tmd_x, got[2], got[3], tmd_v])
    err = _max_error(mine, np.asarray(sc.state))
    assert err < 1e-8, err            # measured 2.8e-16
    np.testing.assert_allclose(sb.dof_amplitude, sc.dof_amplitude, rtol=1e-6)
    # energy in the support's frame: E(t) - E(0) = work of the inertia loads - dissipated
    tr = aj.simulate(based, ag, 3.0, rtol=1e-10, atol=1e-12, energy=True)
    E = np.asarray(tr.mechanical_energy())
    balance = E - E[0] - (np.asarray(tr.work) - np.asarray(tr.dissipated))
    assert np.max(np.abs(balance)) < 1e-7 * np.max(np.abs(np.asarray(tr.work))), balance  # 6.5e-11


def test_base_excitation_of_one_mass_against_its_closed_form_frf():
    """``m ẍ + c ẋ + k x = -m a_g``, ``a_g = A sin ωt``: relative response
    ``X = -m A / (k - m ω² + i c ω)``."""
    m, k, c, A = 2.0, 800.0, 3.0, 0.7
    one = aj.structure_from_matrices([[m]], [[k]], damping=[[c]])
    sysm = aj.StructuralSystem(one, load=aj.BaseExcitation(), observe="x1")
    omegas = np.array([10.0, 19.0, 20.0, 21.0, 35.0])
    fr = aj.frequency_response(sysm, omegas, amplitude=A)
    assert fr.ok.all()
    X = -m * A / (k - m * omegas**2 + 1j * c * omegas)
    np.testing.assert_allclose(fr.states[:, 0], np.imag(X), rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(fr.states[:, 1], np.imag(1j * omegas * X), rtol=1e-8,
                               atol=1e-12)
    np.testing.assert_allclose(fr.amplitude, np.abs(X), rtol=1e-6)     # 6.4e-9


# --------------------------------------------------------------------- a user contact law
def test_user_contact_law_in_an_impact_absorber_against_the_hand_written_ode():
    law = CubicWall(stiffness=5e11, damping=4.0, eps=1e-6, adhesive=True)
    M, k, c, m, gap = 1.0, 1e3, 0.5, 0.2, 1e-3
    sysm = aj.ImpactAbsorber(M=M, k=k, c=c, m=m, gap=gap, contact=law)
    forcing = aj.Harmonic(amplitude=2.0, omega=30.0)
    t1 = 0.8
    ts = np.linspace(0.0, t1, 401)
    tr = aj.simulate(sysm, forcing, t1, ts=ts, rtol=1e-11, atol=1e-13)

    def wall(p, rate):
        delta = 1e-6 * _softplus(p / 1e-6)
        return 5e11 * delta**3 + 4.0 * _sigmoid(p / 1e-6) * rate

    def rhs(t, y):
        x1, v1, x2, v2 = y
        u, w = x2 - x1, v2 - v1
        fc = wall(u - gap, w) - wall(-u - gap, -w)
        a1 = (2.0 * np.sin(30.0 * t) - c * v1 - k * x1 + fc) / M
        return [v1, a1, v2, -fc / m]

    ref = solve_ivp(rhs, (0.0, t1), np.zeros(4), t_eval=ts, method="DOP853", rtol=1e-12,
                    atol=1e-14)
    assert np.max(np.abs(ref.y[2] - ref.y[0])) > 1.05 * gap     # the walls were hit
    err = _max_error(tr.ys[:, [0, 2]], ref.y[[0, 2]].T)
    assert err < 1e-6, err            # measured 7.7e-9


# --------------------------------------------------------------------------- clear errors
def test_clear_errors():
    sysm, _ = _linear_building()
    with pytest.raises(ValueError, match=r"plain function: wrap a periodic one as "
                                         r"PeriodicForcing\(function, omega\)"):
        aj.simulate(sysm, lambda t: 15 * np.sin(80 * t), 0.5)
    with pytest.raises(ValueError, match=r"steady_state needs a periodic forcing.*got "
                                         r"RampedHarmonic \(not periodic\)"):
        aj.steady_state(sysm, aj.RampedHarmonic(amplitude=1.0, omega=5.0, ramp_time=2.0))
    with pytest.raises(ValueError, match=r"wrap it as PeriodicForcing"):
        aj.steady_state(sysm, lambda t: jnp.sin(t))
    with pytest.raises(ValueError, match=r"amplitude must be a force amplitude F0 \[N\] or "
                                         r"a periodic forcing"):
        aj.frequency_response(sysm, [5.0], amplitude=aj.RampedHarmonic(1.0, 5.0, 2.0))
    with pytest.raises(ValueError, match=r"not periodic with 2π/omega"):
        aj.PeriodicForcing(lambda t: jnp.sin(3.0 * t), 2.0)
    with pytest.raises(ValueError, match=r"JAX function of time"):
        aj.PeriodicForcing(lambda t: np.sin(3.0 * t), 3.0)
    with pytest.raises(ValueError, match=r"orders must be 2 integers >= 0"):
        aj.MultiHarmonic([1.0, 2.0], omega=3.0, orders=(1, 1.5))
    b = aj.shear_building([1.0], [1.0])
    with pytest.raises(ValueError, match=r"observe must be given with a BaseExcitation"):
        aj.StructuralSystem(b, load=aj.BaseExcitation())
    with pytest.raises(ValueError, match=r"give participation="):
        aj.StructuralSystem(aj.shear_building([1.0, 1.0], [1.0, 1.0]).modal(1),
                            load=aj.BaseExcitation(), observe="floor1")

    class NoEnergy(aj.AbstractElement):
        dof: str = eqx.field(static=True)
        other: str | None = eqx.field(static=True, default=None)
        name: str | None = eqx.field(static=True, default=None)

        def evaluate(self, x, v, z):
            return jnp.zeros(2), None

    with pytest.raises(TypeError, match="energy"):
        NoEnergy("floor1")


class Relaxation(aj.AbstractSinglePassMethod):
    """A steady-state method written from the public API alone: the period map iterated
    with relaxation, ``x <- x + θ (Φ_T(x) - x)``, until a step is within ``tol``."""

    theta: float = 1.0
    tol: float = 1e-9
    steps: int = eqx.field(static=True, default=500)

    @property
    def retry(self):
        return False

    def initial_state(self, system, forcing):
        return system.linear_guess(forcing)

    def solve(self, system, forcing, x0, cfg, *, with_floquet=True):
        def body(c):
            x, k, _ = c
            xn, _ = aj.orbit_map(system, forcing, x, 1, cfg)
            return x + self.theta * (xn - x), k + 1, jnp.max(jnp.abs(xn - x))

        x, k, _ = jax.lax.while_loop(lambda c: (c[1] < self.steps) & (c[2] > self.tol), body,
                                     (x0, 0, jnp.asarray(jnp.inf)))
        return aj.orbit_result(system, forcing, x, 1, cfg, tol=10 * self.tol, iterations=k,
                               with_floquet=with_floquet)


def test_a_steady_state_method_of_ones_own_finds_shootings_orbits():
    """``Relaxation`` (above) in ``steady_state`` and, vmapped, in ``frequency_response`` on
    the paper's Kelvin–Voigt impact absorber: the orbits, multipliers and stability labels of
    shooting (measured: states 7e-11 and 4e-10, a band's amplitudes 1.2e-8)."""
    system, _ = aj.presets.impact("kelvin_voigt")
    for omega in (30.0, 47.4):
        forcing = aj.Harmonic(amplitude=2.0, omega=omega)
        ref = aj.steady_state(system, forcing, method=aj.Shooting(tol=1e-10))
        ours = aj.steady_state(system, forcing, method=Relaxation())
        assert int(ours.status) == 0 and int(ours.iterations) > 1
        size = np.max(np.abs(np.asarray(ref.state)))
        assert np.max(np.abs(np.asarray(ours.state) - np.asarray(ref.state))) < 1e-8 * size
        np.testing.assert_allclose(np.sort(np.abs(np.asarray(ours.multipliers))),
                                   np.sort(np.abs(np.asarray(ref.multipliers))), rtol=1e-6)
        assert bool(ours.stable) == bool(ref.stable)
    omegas = np.linspace(30.0, 60.0, 8)
    ours = aj.frequency_response(system, omegas, amplitude=2.0, method=Relaxation())
    ref = aj.frequency_response(system, omegas, amplitude=2.0)
    assert np.all(np.asarray(ours.status) == 0)
    np.testing.assert_allclose(np.asarray(ours.amplitude), np.asarray(ref.amplitude),
                               rtol=1e-7)
