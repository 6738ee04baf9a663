r"""Prescribed excitations: a signal of time that loads a system.

The signal is a force [N] on the degrees of freedom a system's ``load`` names, or, for a
``StructuralSystem`` built with ``load=BaseExcitation(...)``, the
acceleration of its support [m/s²].

Two abstract classes make the interface the rest of the library talks to:

- ``AbstractForcing``: any signal. Members ``omega`` (a characteristic angular
  frequency [rad/s]: save grids, solver choice, scales), ``amplitude`` (a typical size of the
  signal, for scales and starting guesses) and ``__call__(t)`` (the value at time ``t`` [s]).
  ``simulate`` accepts any of them.
- ``AbstractPeriodicForcing``: a signal periodic with the fundamental angular frequency
  ``omega``, ``F(t + 2π/ω) = F(t)``. Steady states, sweeps, continuation, attractor maps and
  the design objectives accept any of them. It adds ``with_omega`` (the same signal at
  another fundamental; required), and, with defaults, ``at_phase``, ``with_amplitude`` and
  ``harmonics`` (the Fourier coefficients, used by linear starting guesses).

Concrete forcings: ``Harmonic``, ``MultiHarmonic``, ``PeriodicForcing``
(periodic) and ``RampedHarmonic`` (not periodic).
"""

# (no ``from __future__ import annotations`` here: equinox reads ``AbstractVar`` only from
# evaluated annotations; as strings they would become required dataclass fields of the
# abstract classes, ordered before the concrete classes' own)
import abc
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.checks import as_float, check_scalar, is_traced, nonnegative, positive

# samples per period of the default (sampled) Fourier coefficients and amplitude estimates
FOURIER_SAMPLES = 64
# harmonics kept by the default AbstractPeriodicForcing.harmonics (below the samples' Nyquist)
FOURIER_ORDERS = 16


class AbstractForcing(eqx.Module):
    """A prescribed signal ``F(t)``: a force [N] where the system's load acts, or, for a
    ``StructuralSystem`` built with ``load=BaseExcitation(...)``, the acceleration of its
    support [m/s²].  ``simulate`` accepts any forcing; the steady-state solvers, sweeps,
    continuation, attractor maps and design objectives need a periodic one
    (``AbstractPeriodicForcing``: ``Harmonic``, ``MultiHarmonic``, ``PeriodicForcing``).

    **Members an implementation provides**

    - ``omega``: a characteristic angular frequency [rad/s] of the signal (the fundamental
      of a periodic one). It sets the default save grid of a simulation, the solver choice
      and the velocity scales (``period = 2π/omega``).
    - ``amplitude``: a typical size of ``|F|`` (force [N] or acceleration [m/s²]), used only
      to scale the state for the integrator and to size starting guesses.
    - ``__call__(t)``: the value at time ``t`` [s], a JAX scalar (written with ``jax.numpy``:
      it is traced and differentiated).
    """

    omega: eqx.AbstractVar[object]
    amplitude: eqx.AbstractVar[object]

    @abc.abstractmethod
    def __call__(self, t):
        """The signal at time ``t`` [s]: force [N] or support acceleration [m/s²]."""

    @property
    def period(self):
        """``2π/omega`` [s]."""
        return 2 * jnp.pi / self.omega


class AbstractPeriodicForcing(AbstractForcing):
    r"""A signal periodic with the fundamental angular frequency ``omega`` [rad/s]:
    ``F(t + period) = F(t)``.

    **Members an implementation provides** (besides ``AbstractForcing``'s ``omega``,
    ``amplitude`` and ``__call__``; ``AbstractSampledPeriodicForcing`` gives the last three
    from samples of the signal)

    - ``with_omega(omega)``: the same signal at the fundamental ``omega`` [rad/s]. Frequency
      sweeps, continuation in ``"omega"`` and the design objectives call it at every
      frequency they solve.
    - ``at_phase(phase)``: the signal seen from phase ``phase`` [rad] of its fundamental,
      ``t -> F(t + phase/ω)`` (continuation moves its Poincaré section with it).
    - ``with_amplitude(amplitude)``: the signal scaled to ``amplitude`` (continuation in
      ``"amplitude"``).
    - ``harmonics()``: ``(orders, coefficients)`` with
      $F(t) = \mathrm{Im}\sum_j c_j e^{i k_j \omega t}$ (integer orders ``k_j >= 0``; a
      mean value ``F̄`` is order 0 with ``c = i F̄``). Linear starting guesses superpose the
      response to each.
    """

    @abc.abstractmethod
    def with_omega(self, omega) -> "AbstractPeriodicForcing":
        """The same signal with the fundamental angular frequency ``omega`` [rad/s]."""

    @abc.abstractmethod
    def at_phase(self, phase) -> "AbstractPeriodicForcing":
        """``t -> F(t + phase/omega)``: the signal seen from phase ``phase`` [rad]."""

    @abc.abstractmethod
    def with_amplitude(self, amplitude) -> "AbstractPeriodicForcing":
        """The signal scaled so that its ``amplitude`` is ``amplitude``."""

    @abc.abstractmethod
    def harmonics(self):
        """``(orders, coefficients)``: integer orders (a NumPy array) and complex
        coefficients ``c`` with ``F(t) = Im Σ c e^{i k ω t}`` (class docstring)."""

    @property
    @abc.abstractmethod
    def harmonics_exact(self) -> bool:
        """``True`` when ``harmonics()`` sums to the signal exactly (a closed form), not a
        truncated series: rigid-impact systems then integrate their flights in closed
        form."""


class AbstractSampledPeriodicForcing(AbstractPeriodicForcing):
    """A periodic forcing known through its values: ``at_phase`` and ``with_amplitude``
    wrap it (a shift of time, a gain), and ``harmonics`` are its orders 0 to 16 from 64
    uniform samples of a period.  Subclass it for a signal without closed forms; it needs
    only ``omega``, ``amplitude``, ``__call__`` and ``with_omega``."""

    def at_phase(self, phase) -> "AbstractPeriodicForcing":
        return _Transformed(self, as_float(phase), as_float(1.0))

    def with_amplitude(self, amplitude) -> "AbstractPeriodicForcing":
        gain = as_float(amplitude) / self.amplitude
        return _Transformed(self, as_float(0.0), gain)

    @property
    def harmonics_exact(self) -> bool:
        return False  # orders 0 to FOURIER_ORDERS of sampled values

    def harmonics(self):
        n = FOURIER_SAMPLES
        ts = self.period * jnp.arange(n) / n
        spectrum = jnp.fft.rfft(jax.vmap(self)(ts)) / n
        orders = np.arange(FOURIER_ORDERS + 1)
        c = spectrum[:FOURIER_ORDERS + 1]
        # F = C0 + Σ 2 Re(C_k e^{ikωt}) = Im(i C0) + Σ Im(2i C_k e^{ikωt})
        c = 1j * jnp.where(orders == 0, 1.0, 2.0) * c
        # rounding-level coefficients (a pure tone's other orders) are exactly zero
        return orders, jnp.where(jnp.abs(c) > 1e-13 * jnp.max(jnp.abs(c)), c, 0.0)


class _Transformed(AbstractPeriodicForcing):
    """``t -> gain · F(t + phase/ω)`` of a periodic forcing ``base`` (``at_phase`` and
    ``with_amplitude`` of ``AbstractSampledPeriodicForcing``)."""

    base: AbstractPeriodicForcing
    phase: object
    gain: object

    @property
    def omega(self):
        return self.base.omega

    @property
    def amplitude(self):
        return jnp.abs(self.gain) * self.base.amplitude

    def __call__(self, t):
        return self.gain * self.base(t + self.phase / self.base.omega)

    def with_omega(self, omega):
        return _Transformed(self.base.with_omega(omega), self.phase, self.gain)

    def at_phase(self, phase):
        return _Transformed(self.base, self.phase + phase, self.gain)

    def with_amplitude(self, amplitude):
        return _Transformed(self.base, self.phase, as_float(amplitude) / self.base.amplitude)

    @property
    def harmonics_exact(self) -> bool:
        return self.base.harmonics_exact

    def harmonics(self):
        orders, c = self.base.harmonics()
        return orders, self.gain * c * jnp.exp(1j * jnp.asarray(orders) * self.phase)


def _with_field(module, name, value):
    return eqx.tree_at(lambda m: getattr(m, name), module, as_float(value))


class Harmonic(AbstractPeriodicForcing):
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

    def with_omega(self, omega):
        return _with_field(self, "omega", omega)

    def with_amplitude(self, amplitude):
        return _with_field(self, "amplitude", amplitude)

    def at_phase(self, phase):
        return PhasedHarmonic(amplitude=self.amplitude, omega=self.omega,
                              phase=as_float(phase))

    @property
    def harmonics_exact(self) -> bool:
        return True

    def harmonics(self):
        return np.array([1]), jnp.reshape(self.amplitude, (1,)).astype(complex)


class PhasedHarmonic(AbstractPeriodicForcing):
    r"""$F(t) = F_0 \sin(\omega t + \varphi)$: a ``Harmonic`` seen from phase
    ``phase`` $\varphi$ [rad] of its period (``Harmonic.at_phase``; continuation takes
    its Poincaré section where the absorbers fly free)."""

    amplitude: object
    omega: object
    phase: object

    def __call__(self, t):
        return self.amplitude * jnp.sin(self.omega * t + self.phase)

    def with_omega(self, omega):
        return _with_field(self, "omega", omega)

    def with_amplitude(self, amplitude):
        return _with_field(self, "amplitude", amplitude)

    def at_phase(self, phase):
        return _with_field(self, "phase", self.phase + phase)

    @property
    def harmonics_exact(self) -> bool:
        return True

    def harmonics(self):
        c = self.amplitude * jnp.exp(1j * self.phase)
        return np.array([1]), jnp.reshape(c, (1,))


class MultiHarmonic(AbstractPeriodicForcing):
    r"""A sum of harmonics of one fundamental:
    $F(t) = \sum_j A_j \sin(k_j \omega t + \varphi_j)$, periodic with $2\pi/\omega$.

    **Arguments**

    - ``amplitudes``: $A_j$ [N] (or [m/s²] under a base excitation), one per harmonic.
    - ``omega``: the fundamental $\omega$ [rad/s].
    - ``phases``: $\varphi_j$ [rad] (default all 0).
    - ``orders``: the integer orders $k_j \ge 0$ (default ``1, 2, …``); order 0 is a
      constant ``A sin φ``.

    ``amplitude`` (the typical size used for scales) is $\sum_j |A_j|$, a bound on $|F|$.

    ```python
    f = MultiHarmonic([2.0, 0.5], omega=40.0, orders=(1, 3), phases=(0.0, 0.3))
    f(0.01)   # 2 sin(0.4) + 0.5 sin(1.2 + 0.3)
    ```
    """

    amplitudes: object
    omega: object
    phases: object
    orders: tuple = eqx.field(static=True)

    def __init__(self, amplitudes, omega, phases=None, orders=None):
        amps = as_float(amplitudes)
        if not is_traced(amps) and amps.ndim != 1:
            raise ValueError(f"MultiHarmonic.amplitudes must be a 1-D array, got shape "
                             f"{amps.shape}")
        n = amps.shape[0]
        if orders is None:
            orders = tuple(range(1, n + 1))
        shown = orders
        try:
            given = np.asarray(orders, dtype=float).reshape(-1)
            bad = bool(np.any(given != np.round(given)) or np.any(given < 0))
            orders = tuple(int(k) for k in given)
        except (TypeError, ValueError):
            bad = True
        if bad or len(orders) != n:
            raise ValueError(f"MultiHarmonic.orders must be {n} integers >= 0 (one per "
                             f"amplitude), got {shown!r}")
        phases = jnp.zeros((n,)) if phases is None else as_float(phases)
        if not is_traced(phases) and phases.shape != (n,):
            raise ValueError(f"MultiHarmonic.phases must have one value per amplitude ({n}), "
                             f"got shape {phases.shape}")
        self.amplitudes = amps
        self.omega = as_float(omega)
        self.phases = phases
        self.orders = orders

    def __check_init__(self):
        positive("MultiHarmonic", "omega", self.omega)
        for name in ("amplitudes", "phases"):
            v = getattr(self, name)
            if not is_traced(v) and not np.all(np.isfinite(np.asarray(v))):
                raise ValueError(f"MultiHarmonic.{name} must be finite, got {v!r}")

    @property
    def amplitude(self):
        return jnp.sum(jnp.abs(self.amplitudes))

    def __call__(self, t):
        k = jnp.asarray(self.orders, dtype=float)
        return jnp.sum(self.amplitudes * jnp.sin(k * self.omega * t + self.phases))

    def with_omega(self, omega):
        return _with_field(self, "omega", omega)

    def with_amplitude(self, amplitude):
        return eqx.tree_at(lambda f: f.amplitudes, self,
                           self.amplitudes * (as_float(amplitude) / self.amplitude))

    def at_phase(self, phase):
        k = jnp.asarray(self.orders, dtype=float)
        return eqx.tree_at(lambda f: f.phases, self, self.phases + k * phase)

    @property
    def harmonics_exact(self) -> bool:
        return True

    def harmonics(self):
        return np.asarray(self.orders, dtype=int), self.amplitudes * jnp.exp(1j * self.phases)


class PeriodicForcing(AbstractSampledPeriodicForcing):
    r"""Any periodic signal given as a JAX function of time: $F(t) = f(t)$ with
    $f(t + 2\pi/\omega) = f(t)$.

    **Arguments**

    - ``function``: ``t [s] -> F`` [N] (or [m/s²] under a base excitation), written with
      ``jax.numpy`` (it is traced, vmapped and differentiated); a scalar per time.
    - ``omega``: its fundamental angular frequency [rad/s]. Checked on construction:
      ``f(t + 2π/ω)`` must equal ``f(t)``.

    ``with_omega`` rescales time, ``t -> f(t ω'/ω)``: the same waveform at another
    fundamental (field ``time_scale``, 1 as constructed). ``amplitude`` is ``max |f|`` over
    64 uniform samples of a period.

    ```python
    import jax.numpy as jnp
    square = PeriodicForcing(lambda t: 3.0 * jnp.tanh(20 * jnp.sin(50.0 * t)), omega=50.0)
    ```
    """

    function: Callable = eqx.field(static=True)
    omega: object
    time_scale: object

    def __init__(self, function, omega):
        if not callable(function):
            raise ValueError(f"PeriodicForcing.function must be a function of time, got "
                             f"{type(function).__name__}")
        self.function = function
        self.omega = as_float(omega)
        self.time_scale = as_float(1.0)

    def __check_init__(self):
        positive("PeriodicForcing", "omega", self.omega)
        if is_traced(self.omega) or is_traced(self.time_scale):
            return
        try:
            out = jax.eval_shape(self.function, jnp.zeros(()))
        except Exception as e:
            first = (str(e).splitlines() or [""])[0]
            raise ValueError(f"PeriodicForcing.function must be a JAX function of time "
                             f"(written with jax.numpy, not numpy or math): calling it on a "
                             f"traced time failed with {type(e).__name__}: {first}") from None
        if getattr(out, "shape", None) != ():
            raise ValueError(f"PeriodicForcing.function must return a scalar per time, got "
                             f"shape {getattr(out, 'shape', None)}")
        T = float(self.period)
        ts = T * np.array([0.0, 0.137, 0.29, 0.51, 0.77])
        now = np.asarray(jax.vmap(self)(jnp.asarray(ts)))
        later = np.asarray(jax.vmap(self)(jnp.asarray(ts + T)))
        size = max(float(np.max(np.abs(now))), 1e-300)
        if not np.all(np.isfinite(now)) or np.max(np.abs(later - now)) > 1e-6 * size:
            raise ValueError(f"PeriodicForcing.function is not periodic with 2π/omega = "
                             f"{T:.6g} s (omega = {float(self.omega):g} rad/s): f(t + T) - "
                             f"f(t) reaches {np.max(np.abs(later - now)):.3g}")

    @property
    def amplitude(self):
        n = FOURIER_SAMPLES
        return jnp.max(jnp.abs(jax.vmap(self)(self.period * jnp.arange(n) / n)))

    def __call__(self, t):
        return self.function(self.time_scale * t)

    def with_omega(self, omega):
        omega = as_float(omega)
        out = eqx.tree_at(lambda f: f.time_scale, self, self.time_scale * omega / self.omega)
        return eqx.tree_at(lambda f: f.omega, out, omega)


class RampedHarmonic(AbstractForcing):
    r"""Harmonic force whose amplitude grows linearly from 0 to ``amplitude`` over
    ``ramp_time`` and then stays constant:
    $F(t) = F_0 \min(t/T_r, 1)\sin(\omega t)$ (not periodic: [`simulate`][absorber_jax.simulate]
    only).

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


def at_frequency(forcing_or_amplitude, omega) -> "AbstractPeriodicForcing":
    """The periodic forcing a sweep or a design objective solves at ``omega`` [rad/s]:
    ``forcing.with_omega(omega)`` for a periodic forcing, ``Harmonic(F0, omega)`` for a force
    amplitude ``F0`` [N]."""
    if isinstance(forcing_or_amplitude, AbstractPeriodicForcing):
        return forcing_or_amplitude.with_omega(omega)
    return Harmonic(amplitude=forcing_or_amplitude, omega=omega)


def sweep_shape(forcing_or_amplitude, where):
    """What a sweep or design objective carries into its compiled calls: a periodic forcing
    as given, or a force amplitude as a float64 array (checked ``>= 0``, ValueError naming
    ``where`` otherwise)."""
    if isinstance(forcing_or_amplitude, AbstractPeriodicForcing):
        return forcing_or_amplitude
    if isinstance(forcing_or_amplitude, AbstractForcing) or callable(forcing_or_amplitude):
        raise ValueError(f"{where}: amplitude must be a force amplitude F0 [N] or a periodic "
                         f"forcing (Harmonic, MultiHarmonic, PeriodicForcing or another "
                         f"AbstractPeriodicForcing), got {type(forcing_or_amplitude).__name__}")
    check_scalar(where, "amplitude", forcing_or_amplitude, lo=0.0)
    return jnp.asarray(forcing_or_amplitude, dtype=float)


def check_periodic(forcing, where):
    """ValueError unless ``forcing`` is an ``AbstractPeriodicForcing``, naming what is
    allowed (a plain function is told to wrap itself in ``PeriodicForcing``)."""
    if isinstance(forcing, AbstractPeriodicForcing):
        return
    allowed = ("forcing must be a Harmonic, MultiHarmonic, PeriodicForcing or another "
               "AbstractPeriodicForcing")
    if callable(forcing) and not isinstance(forcing, AbstractForcing):
        raise ValueError(f"{where} needs a periodic forcing: {allowed}, got a plain function; "
                         f"wrap it as PeriodicForcing(function, omega) with its fundamental "
                         f"angular frequency omega [rad/s]")
    what = " (not periodic)" if isinstance(forcing, AbstractForcing) else ""
    raise ValueError(f"{where} needs a periodic forcing: {allowed}, got "
                     f"{type(forcing).__name__}{what}")
