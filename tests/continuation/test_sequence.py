"""Orbits with a fixed sequence of events (``_continuation.sequence``): the multiple-shooting
problem over the flights between rigid impacts, against the event-exact reference of
tests/reference_impacts.py."""

import jax.numpy as jnp
import numpy as np
from reference_impacts import RigidImpactAbsorber

import absorber_jax as aj
from absorber_jax._continuation import sequence
from absorber_jax._integration.flow import make_config, state_scale

SCENE = dict(M=1.0, k=1e3, c=0.5, m=0.2, gap=2e-3)
F0, OMEGA, E = 3.0, 22.0, 0.947


def test_a_fixed_sequence_orbit_is_the_event_exact_periodic_orbit():
    # several impacts a period: the sequence of the hybrid orbit from a perturbed start,
    # solved with its events held fixed, against the event-exact reference
    system = aj.ImpactAbsorber(**SCENE, contact=aj.Restitution(E))
    forcing = aj.Harmonic(amplitude=F0, omega=OMEGA)
    ss = aj.steady_state(system, forcing)
    x = np.asarray(system.to_internal(jnp.asarray(ss.state)))
    sc = np.asarray(state_scale(system, forcing))
    T = float(forcing.period)
    cfg = make_config(system, forcing)
    times, modes, status = sequence.event_log(system, forcing, jnp.asarray(x / sc),
                                              jnp.asarray(T), cfg)
    times = np.asarray(times)
    K = int(np.isfinite(times).sum())
    assert int(status) == 0 and K == int(ss.impacts) >= 2
    theta = np.concatenate([times[:K] / T, np.ones(sequence.SLOTS - K)])
    seg = np.concatenate([np.asarray(modes)[:K + 1], np.zeros(sequence.SLOTS - K, int)])
    active = np.arange(sequence.SLOTS) < K
    guess = np.concatenate([x / sc * (1 + 1e-3), theta + 1e-3 * active])
    u, status, res, rates = sequence.solve_sequence(system, forcing, 1, jnp.asarray(guess),
                                                    jnp.asarray(seg), jnp.asarray(active),
                                                    cfg)
    assert int(status) == 0 and float(res) < 1e-10
    u = np.asarray(u)
    rates = np.asarray(rates)
    assert np.all(rates[:K] > 1.0)          # every impact reached moving into its wall
    assert np.all(np.abs(np.diff(u[4:4 + K])) > 1e-3)     # distinct, ordered events
    y0 = system.to_public(jnp.asarray(u[:4] * sc))
    ref = RigidImpactAbsorber(SCENE["M"], SCENE["k"], SCENE["c"], SCENE["m"], SCENE["gap"],
                              E, F0, OMEGA)
    y, events = ref.run(np.asarray(y0), 0.0, T)
    scale = np.array([1.0, OMEGA, 1.0, OMEGA]) * SCENE["gap"]
    assert np.max(np.abs(y[-1] - np.asarray(y0)) / scale) < 1e-9
    t_ref = np.array([t for t, k in events if k == "impact"])
    assert np.max(np.abs(t_ref - u[4:4 + K] * T)) < 1e-9 * T


def test_an_event_inserted_at_a_grazing_apex_splits_its_segment():
    times = np.array([0.2, 0.5, np.inf, np.inf])
    modes = np.array([0, 0, 0, 0])
    theta, seg, active = sequence.sequence_with(times, modes, 0.3, 1.0)
    K = int(active.sum())
    assert K == 3 and np.allclose(theta[:K], [0.2, 0.3, 0.5]) and np.all(theta[K:] == 1.0)
    assert seg.shape == (sequence.SLOTS + 1,) and theta.shape == (sequence.SLOTS,)
    full = np.concatenate([np.linspace(0.01, 0.99, sequence.SLOTS), [np.inf]])
    assert sequence.sequence_with(full, np.zeros(sequence.SLOTS + 1, int), 0.5, 1.0) is None
