"""External forcing of the primary mass."""

from __future__ import annotations

import abc

import equinox as eqx
import jax.numpy as jnp

from .._core.checks import as_float, nonnegative, positive


class AbstractForcing(eqx.Module):
    """A force ``F(t)`` [N] on the primary with a fundamental angular frequency ``omega``
    [rad/s] (used for periods, Poincaré sections and save grids)."""

    omega: eqx.AbstractVar[object]
    amplitude: eqx.AbstractVar[object]  # force amplitude F0 [N]

    @abc.abstractmethod
    def __call__(self, t):
        """Force [N] at time ``t`` [s]."""

    @property
    def period(self):
        return 2 * jnp.pi / self.omega


class Harmonic(AbstractForcing):
    r"""Harmonic force $F(t) = F_0 \sin(\omega t)$ (the paper's excitation).

    - ``amplitude``: $F_0$ [N] (Tables 1–3: 2 N).
    - ``omega``: $\omega$ [rad/s] (Tables 1–3: 47.4).

    ```python
    f = Harmonic(amplitude=2.0, omega=47.4)
    f(0.01)   # 2 sin(0.474) = 0.913 N
    ```
    """

    amplitude: object = eqx.field(converter=as_float)
    omega: object = eqx.field(converter=as_float)

    def __check_init__(self):
        nonnegative("Harmonic", "amplitude", self.amplitude)
        positive("Harmonic", "omega", self.omega)

    def __call__(self, t):
        return self.amplitude * jnp.sin(self.omega * t)


class PhasedHarmonic(AbstractForcing):
    r"""$F(t) = F_0 \sin(\omega t + \varphi)$: a :class:`Harmonic` seen from a Poincaré
    section at forcing phase ``phase`` $\varphi$ [rad] (internal: continuation takes its
    section where the absorbers fly free, see ``_continuation``)."""

    amplitude: object
    omega: object
    phase: object

    def __call__(self, t):
        return self.amplitude * jnp.sin(self.omega * t + self.phase)


class RampedHarmonic(AbstractForcing):
    r"""Harmonic force whose amplitude grows linearly from 0 to ``amplitude`` over
    ``ramp_time`` and then stays constant:
    $F(t) = F_0 \min(t/T_r, 1)\sin(\omega t)$.

    Used for the friction scenes: a slow ramp passes through the sticking threshold, so one
    run shows the jammed, partially gliding and totally gliding absorber.

    ```python
    f = RampedHarmonic(amplitude=60.0, omega=40.0, ramp_time=20.0)
    f(10.0)   # 30 sin(400) N
    ```
    """

    amplitude: object = eqx.field(converter=as_float)
    omega: object = eqx.field(converter=as_float)
    ramp_time: object = eqx.field(converter=as_float)

    def __check_init__(self):
        nonnegative("RampedHarmonic", "amplitude", self.amplitude)
        positive("RampedHarmonic", "omega", self.omega)
        positive("RampedHarmonic", "ramp_time", self.ramp_time)

    def envelope(self, t):
        return self.amplitude * jnp.clip(t / self.ramp_time, 0.0, 1.0)

    def __call__(self, t):
        return self.envelope(t) * jnp.sin(self.omega * t)
