"""Cost of the band objective's value and gradient against the forward sweep alone.

Table 1 impact scene, 64 frequencies over 25–45 rad/s, objective = smooth peak, gradient with
respect to k1, c1, m (three parameters, forward mode through the implicit orbit solve), side
by side in one run.  The target: the value and gradient cost at most 2x the sweep.

    python scripts/benchmark_grad.py [--repeats 3]
"""

import argparse
import time

import jax
import jax.numpy as jnp
import numpy as np

import absorber_jax as aj
from absorber_jax._design import base as _base
from absorber_jax._design import tune as _design
from absorber_jax._periodic.steady import make_config
from absorber_jax._systems.forcing import Harmonic


def main(repeats):
    system, _ = aj.presets.impact("kelvin_voigt")
    om = jnp.linspace(25.0, 45.0, 64)
    names = ("k1", "c1", "m")
    cfg = make_config(system, Harmonic(amplitude=2.0, omega=25.0), None, 1e-10, 1e-10)
    guesses = jnp.full((64, 4), jnp.nan, dtype=jnp.float64)
    amp = jnp.asarray(2.0)

    @jax.jit
    def forward(system):
        a, _, st, _ = _base.band_amplitudes(system, om, amp, guesses, cfg,
                                            _base.shooting_for_design(1e-7, 40))
        return _base.band_objective(a, "peak"), st

    reparam = _base.Reparam(lo=jnp.zeros(3), hi=jnp.ones(3), bounded=jnp.zeros(3, bool),
                               identity=jnp.zeros(3, bool))
    u = jnp.log(jnp.array([float(aj.get_param(system, k)) for k in names]))

    def vg():
        return _design._value_and_jac(system, names, reparam, u, om, amp, guesses, cfg,
                                      _base.shooting_for_design(1e-7, 40), "peak", 2e-3)

    def timed(f):
        jax.block_until_ready(f())  # compile
        ts = []
        for _ in range(repeats):
            t = time.perf_counter()
            jax.block_until_ready(f())
            ts.append(time.perf_counter() - t)
        return min(ts)

    t_fwd = timed(lambda: forward(system))
    t_vg = timed(vg)
    val, g, _ = vg()
    print(f"forward sweep (64 frequencies, objective only): {t_fwd:.3f} s")
    print(f"value and gradient (3 parameters, forward mode): {t_vg:.3f} s")
    print(f"ratio: {t_vg / t_fwd:.2f}x   objective {float(val):.6e}, gradient {np.asarray(g)}")
    return t_fwd, t_vg


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    main(ap.parse_args().repeats)
