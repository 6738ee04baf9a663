r"""Smooth replacements of the nonsmooth operations used by contact and friction laws.

Each takes a smoothing length ``eps`` in the unit of its argument and converges to the
nonsmooth operation as ``eps -> 0``.  ``relu(x) - relu(-x) = x`` holds exactly, so a
zero clearance recovers a linear spring exactly.
"""

import jax
import jax.numpy as jnp


def smooth_relu(x, eps):
    r"""$\max(0, x) \approx \varepsilon\,\mathrm{softplus}(x/\varepsilon)$, error at most
    $\varepsilon\ln 2$."""
    return eps * jax.nn.softplus(x / eps)


def smooth_gate(x, eps):
    r"""Heaviside step $H(x) \approx \mathrm{sigmoid}(x/\varepsilon)$, the derivative of
    ``smooth_relu``."""
    return jax.nn.sigmoid(x / eps)


def smooth_sign(v, eps):
    r"""$\mathrm{sign}(v) \approx \tanh(v/\varepsilon)$."""
    return jnp.tanh(v / eps)


def smooth_abs(v, eps):
    r"""$|v| \approx v\tanh(v/\varepsilon)$: exactly zero at ``v = 0``, so bristle models keep
    true sticking (``sqrt(v**2 + eps**2)`` would make them creep)."""
    return v * jnp.tanh(v / eps)


def abs_or_smooth(v, eps):
    r"""$|v|$ exactly where ``eps == 0``, else ``smooth_abs`` (``eps`` may be traced: both
    branches are evaluated, the unused one on a safe divisor, so gradients stay finite)."""
    smooth = eps > 0
    return jnp.where(smooth, smooth_abs(v, jnp.where(smooth, eps, 1.0)), jnp.abs(v))


def smooth_clip_positive(f, scale):
    r"""Force clipped at zero, smoothly: $f\,\mathrm{sigmoid}(f/s)$.

    Exactly zero at ``f = 0`` (so no force appears out of contact); tends to ``f`` for
    ``f >> s`` and to ``0`` for ``f << -s`` (its most negative value is ``-0.28 s``)."""
    return f * jax.nn.sigmoid(f / scale)
