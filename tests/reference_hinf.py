"""Independent H-infinity optimum of a tuned mass damper on an undamped primary, from the
closed-form receptance only (numpy/scipy; nothing here imports absorber_jax).

Primary ``M, k`` (natural frequency ``wn``), absorber ``m = mu M`` tuned to frequency ratio
``f = sqrt(k_a/m)/wn`` with damping ratio ``zeta = c_a / (2 sqrt(k_a m))``.  The normalised
primary amplitude ``|X1| k / F0`` has two peaks; the H-infinity optimum minimises the larger.
"""

import numpy as np
from scipy.optimize import minimize, minimize_scalar


def receptance(mu, f, zeta, r):
    """``|X1| k / F0`` at frequency ratio ``r = w / wn`` (closed form, two degrees of
    freedom)."""
    g = 2 * zeta * f * r * 1j
    num = f**2 - r**2 + g
    den = (1 - r**2) * (f**2 - r**2 + g) - mu * r**2 * (f**2 + g)
    return np.abs(num / den)


def peaks(mu, f, zeta, lo=0.5, hi=1.6):
    """The local maxima ``(r, height)`` of the receptance on ``[lo, hi]``: a dense grid, each
    maximum refined by bounded Brent to 1e-13."""
    r = np.linspace(lo, hi, 4001)
    h = receptance(mu, f, zeta, r)
    out = []
    for i in np.flatnonzero((h[1:-1] >= h[:-2]) & (h[1:-1] > h[2:])) + 1:
        res = minimize_scalar(lambda x: -receptance(mu, f, zeta, x), bounds=(r[i - 1], r[i + 1]),
                              method="bounded", options=dict(xatol=1e-13))
        out.append((res.x, -res.fun))
    return out


def h_infinity(mu):
    """``(f, zeta, peak)`` minimising the larger peak: Nelder–Mead on the max of the two
    refined peaks, from Den Hartog's approximate values."""
    x0 = (1 / (1 + mu), np.sqrt(3 * mu / (8 * (1 + mu))))
    obj = lambda p: max(h for _, h in peaks(mu, *p))  # noqa: E731
    res = minimize(obj, x0, method="Nelder-Mead",
                   options=dict(xatol=1e-11, fatol=1e-14, maxiter=4000))
    return res.x[0], res.x[1], res.fun


def nishihara_asami(mu):
    """The published closed form of the same optimum (Nishihara & Asami, J. Vib. Acoust.
    124 (2002) 576): ``(f, zeta)``."""
    s = np.sqrt(4 + 3 * mu)
    f = 2 / (1 + mu) * np.sqrt(2 * (16 + 23 * mu + 9 * mu**2 + 2 * (2 + mu) * s)
                               / (3 * (64 + 80 * mu + 27 * mu**2)))
    zeta = 0.25 * np.sqrt((8 + 9 * mu - 4 * s) / (1 + mu))
    return f, zeta
