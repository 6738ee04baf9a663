"""Exact piecewise-linear reference for the jumps of a hardening oscillator with hysteresis.

numpy/scipy only; nothing here imports absorber_jax.

Scene (one DOF, x = [q, q']):
    m q'' + c q' + k q + f_nl(q) = F0 sin(W t),   f_nl(q) = k_c (q - g) if q > g else 0
    defaults m = 1, k = 1, c = 0.02, F0 = 0.05, k_c = 3, g = 0.5  (one-sided spring, gap g).
Two linear regimes (OPEN q <= g, CLOSED q > g); the force is continuous at q = g.

Method.  Inside a regime the motion is known in closed form: particular solution
qp = P sin Wt + Q cos Wt + qs (P + iQ = F0/m / (kr - W^2 + i c W/m)) plus the homogeneous part
e^{A tau} y0 = e^{-s tau} [cos(wd tau) I + sin(wd tau)/wd (A + s I)] y0 (the eigen form; checked
against scipy expm of the augmented 5x5 system z = [q, q', sin Wt, cos Wt, 1], ~2e-14).
Switches q = g are bracketed on a grid of 1/40 of the fastest period (closed-regime natural
period or forcing period), grazing double crossings inside one grid step caught through the
sign change of q' towards the boundary, and located by brentq (xtol 1e-15).  period_map(x, W)
is the exact state after T = 2 pi/W; monodromy = product of the regime transition matrices
(saltation = identity, continuous force); det(monodromy) = exp(-c T/m) on every orbit, so an
instability can only come from a real multiplier through +1 (fold) or a pair through -1 (flip).

slow_sweep_jumps("up" | "down"): a stepped marching sweep as on a shaker, no continuation:
march (repeated period_map) to the settled Poincare point at each W, steps 0.05 outside
[0.95, 1.5] and 0.01 inside, jump = an amplitude drop ("up") / rise ("down") confirmed by
hysteresis (stepping back from the new state lands on a second attractor), refined by
bisection to |W_b - W_a| < 1e-6 W_a, marching from the old-branch state at W_a and classifying
by amplitude (cap 20000 periods near the fold; critical slowing down).  Near the lower fold a
0.01 step kicks the state across the separatrix early (at W = 1.05, 2.3e-3 above the fold: the
saddle is close and the fold sits next to grazing); such step-induced jumps are detected (a step
< 1e-6 from W_a to W_b stays on the branch) and the sweep resumes with small doubling steps.

validate() (run this file): (a) period_map vs DOP853 with events, monodromy vs central
differences, exact vs sampled amplitude; (b) the folds by pseudo-arclength continuation of the
fixed point of period_map (y = (q0, q0', W), exact monodromy, dP/dW by central differences),
each refined twice on the branch: extremum of W along the arclength parameter (bounded Brent)
and det(M - I) = 0 (brentq); (c) Floquet multipliers along the branches and near each fold.

Figures (default parameters; `python tests/reference_jumps.py`, one core, 2-core machine
shared with a CI run):
    (a) period_map vs DOP853 (rtol 1e-12, atol 1e-14): 8e-13 relative (2-3 switches/period);
        closed form vs expm 2e-14; monodromy vs central differences 5e-10.
    folds (continuation; extremum of W and det(M - I) = 0 agree to 2e-16):
        upper fold W = 1.2506890291, amplitude 1.9635215, multipliers (1, 0.9044)
        lower fold W = 1.0477271795, amplitude 0.5007061, multipliers (1, 0.8870);
        the lower fold is a near-grazing fold: max q - g = 7.0e-4 there, and the non-resonant
        branch touches the stop (grazing) only at W = 1.0477498718, 2.3e-5 above the fold
        (the resonant branch leaves contact at W = 0.9496421464).
    jumps (slow_sweep_jumps):
        "up"  : W = 1.2506890869, bracket [1.2506884766, 1.2506896973], amplitude 1.96436 ->
                0.08853; jump - fold = +5.8e-8 (fold inside the bracket); 3.3-5 s, 47203 periods
        "down": W = 1.0477272656, bracket [1.0477270036, 1.0477275275], amplitude 0.50061 ->
                0.68253; jump - fold = +8.6e-8 (fold inside the bracket); 1.2-1.8 s, 39682
                periods, 2 step-induced early jumps repaired
    stability: the resonant branch is stable from W = 0.8 up to the upper fold (max |mu| < 1,
        no flip: a complex pair, |mu| = exp(-c T/2) = 0.92..0.95, turning real near the fold,
        (0.98830, 0.91511) at fold - 1e-4, (0.99895, 0.90536) at fold - 1e-6); the middle branch
        is a saddle throughout (|mu|max >= 1.0036); the non-resonant branch is stable from the
        lower fold to W = 1.62 (complex pair, |mu| = 0.9418 down to fold + 2e-7: the real pair
        and the multiplier +1 appear only within 2e-7 of this sharp near-grazing fold).  So
        the jump picture holds: jumps = folds to < 1e-7.
    Other parameter sets checked (|jump - fold| < 5e-7 for both jumps; up to 12 s loaded):
        (c, F0) = (0.05, 0.1): folds 1.0917870883, 1.2332089157;  F0 = 0.2: 1.1815276411,
        1.3143382018;  k_c = 10: 1.0477478433, 1.4014997103 (the lower fold stays near-grazing:
        max q - g = 3e-3, 1.3e-2, 6e-5 there).
"""

import math
import os
import time
from functools import lru_cache

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # 2x2 / 5x5 matrices: threads only cost
import numpy as np  # noqa: E402
from scipy.optimize import brentq, minimize_scalar  # noqa: E402

PARAMS = dict(m=1.0, k=1.0, c=0.02, F0=0.05, k_c=3.0, g=0.5)
OPEN, CLOSED = 0, 1
XT = dict(xtol=1e-15, rtol=4 * np.finfo(float).eps, maxiter=200)  # brentq tolerances
NGRID = 40  # switch-bracketing grid: NGRID points per fastest period (natural or forcing)


def _p(kw):
    """Full parameter tuple (m, k, c, F0, k_c, g) from keyword overrides of PARAMS."""
    bad = set(kw) - set(PARAMS)
    if bad:
        raise TypeError(f"unknown parameters {sorted(bad)}")
    d = {**PARAMS, **kw}
    return tuple(float(d[n]) for n in ("m", "k", "c", "F0", "k_c", "g"))


# ---------------------------------------------------------------- one linear regime, exactly
@lru_cache(maxsize=256)
def _regime(p, r, W):
    """Closed-form data of regime r (OPEN: q <= g, CLOSED: q > g) at forcing frequency W.

    q'' + 2 s q' + kr q = fm sin(W t) + kr qs,  s = c / 2m, kr = (k + r k_c) / m,
    qs = r k_c g / (k + r k_c) (static offset), fm = F0 / m.
    Particular solution  qp = P sin Wt + Q cos Wt + qs,  P + iQ = fm / (kr - W^2 + 2 i s W);
    homogeneous part (eigen form of x' = A x, A = [[0, 1], [-kr, -2s]], lambda = -s +- i wd):
    exp(A tau) = e^{-s tau} [cos(wd tau) I + sin(wd tau)/wd (A + s I)].
    Grid arrays on tau_j = j dt, j = 0..n, n dt >= T: cos/sin(W tau_j), e^{-s tau} cos/sin/wd.
    """
    m, k, c, F0, kc, g = p
    kr = (k + r * kc) / m
    s = c / (2 * m)
    if kr <= s * s:
        raise ValueError("overdamped regime: the eigen form here assumes wd > 0")
    wd = math.sqrt(kr - s * s)
    Z = (F0 / m) / complex(kr - W * W, 2 * s * W)
    qs = r * kc * g / (k + r * kc)
    wmax = max(math.sqrt((k + kc) / m), math.sqrt(k / m), W)
    dt = 2 * math.pi / wmax / NGRID
    n = int(math.ceil(2 * math.pi / W / dt)) + 1
    tau = np.arange(n + 1) * dt
    e = np.exp(-s * tau)
    grid = (
        tau,
        np.cos(W * tau),
        np.sin(W * tau),
        e * np.cos(wd * tau),
        e * np.sin(wd * tau) / wd,
    )
    return dict(kr=kr, s=s, wd=wd, P=Z.real, Q=Z.imag, qs=qs, dt=dt, grid=grid, W=W)


def _coef(R, ta, q0, v0):
    """Coefficients of q(ta + tau) = a1 cos W tau + a2 sin W tau + qs + b1 E_c + b2 E_s and
    v(ta + tau) = W (a2 cos W tau - a1 sin W tau) + b1v E_c + b2v E_s,
    E_c = e^{-s tau} cos wd tau, E_s = e^{-s tau} sin(wd tau)/wd."""
    W = R["W"]
    sa, ca = math.sin(W * ta), math.cos(W * ta)
    a1 = R["P"] * sa + R["Q"] * ca
    a2 = R["P"] * ca - R["Q"] * sa
    yq = q0 - a1 - R["qs"]
    yv = v0 - W * a2
    s, kr = R["s"], R["kr"]
    return (a1, a2, R["qs"], yq, s * yq + yv, yv, -(kr * yq + s * yv))


def _qv_scalar(R, cf, tau):
    """q, v at ta + tau (scalar, math module)."""
    a1, a2, qs, b1, b2, b1v, b2v = cf
    W, s, wd = R["W"], R["s"], R["wd"]
    cw, sw = math.cos(W * tau), math.sin(W * tau)
    e = math.exp(-s * tau)
    ec, es = e * math.cos(wd * tau), e * math.sin(wd * tau) / wd
    return (
        a1 * cw + a2 * sw + qs + b1 * ec + b2 * es,
        W * (a2 * cw - a1 * sw) + b1v * ec + b2v * es,
    )


def _qv_grid(R, cf, n):
    """q, v on the first n + 1 grid points tau_j = j dt (numpy)."""
    a1, a2, qs, b1, b2, b1v, b2v = cf
    tau, cw, sw, ec, es = (x[: n + 1] for x in R["grid"])
    W = R["W"]
    return (
        tau,
        a1 * cw + a2 * sw + qs + b1 * ec + b2 * es,
        W * (a2 * cw - a1 * sw) + b1v * ec + b2v * es,
    )


def _phi(R, tau):
    """2x2 transition matrix exp(A tau) of the regime (closed form)."""
    s, wd, kr = R["s"], R["wd"], R["kr"]
    e = math.exp(-s * tau)
    C, S = e * math.cos(wd * tau), e * math.sin(wd * tau) / wd
    return np.array([[C + s * S, S], [-kr * S, C - s * S]])


def _next_switch(R, r, cf, span, g):
    """First switch time tau in (0, span] of regime r from coefficients cf, or None.
    Leaving: OPEN -> q - g > 0 (sg = +1), CLOSED -> q - g < 0 (sg = -1).  Bracketed on the
    grid; a grazing double crossing inside one grid step is caught through the extremum of q
    (sign change of q' towards the boundary), then brentq to ~1e-15."""
    sg = 1.0 if r == OPEN else -1.0
    dt = R["dt"]
    n = max(1, int(math.ceil(span / dt)))
    tau, q, v = _qv_grid(R, cf, n)
    h = sg * (q - g)
    fq = lambda x: _qv_scalar(R, cf, x)[0] - g
    fv = lambda x: _qv_scalar(R, cf, x)[1]
    out = h[1:] > 0  # sample 0 belongs to the regime by definition (it may be a switch point)
    kout = int(np.argmax(out)) + 1 if out.any() else n + 1
    # extremum towards the boundary (sg v from > 0 to <= 0) before the first outside sample
    sv = sg * v
    for kk in np.nonzero((sv[:-1] > 0) & (sv[1:] <= 0))[0][:8]:
        k1 = kk + 1
        if k1 >= kout:
            break
        ts = brentq(fv, tau[k1 - 1], tau[k1], **XT)
        if ts > span:
            break
        if sg * fq(ts) > 0:
            return brentq(fq, tau[k1 - 1], ts, **XT)
    if kout > n:
        return None
    lo = tau[kout - 1]
    if kout == 1 and sv[0] < 0 < sv[1]:  # re-exit within the first step: start at the extremum
        lo = brentq(fv, 0.0, tau[1], **XT)
    ts = brentq(fq, lo, tau[kout], **XT)
    return ts if ts <= span else None


def _regime0(x, g):
    return CLOSED if x[0] > g or (x[0] == g and x[1] > 0) else OPEN


def _flow(x0, W, p, jac=False):
    """Exact flow over one period [0, T]: (x(T), segments [(ta, tau, r, cf)], monodromy)."""
    g = p[5]
    T = 2 * math.pi / W
    Rs = (_regime(p, OPEN, W), _regime(p, CLOSED, W))
    q, v = float(x0[0]), float(x0[1])
    r, t, segs = _regime0((q, v), g), 0.0, []
    M = np.eye(2) if jac else None
    while True:
        R = Rs[r]
        cf = _coef(R, t, q, v)
        tau = _next_switch(R, r, cf, T - t, g)
        hit = tau is not None
        if not hit:
            tau = T - t
        segs.append((t, tau, r, cf))
        q, v = _qv_scalar(R, cf, tau)
        if jac:
            M = _phi(R, tau) @ M  # saltation = identity: the force is continuous at q = g
        if not hit:
            return np.array([q, v]), segs, M
        t, r = t + tau, 1 - r
        q = g  # exactly on the switching surface
        if len(segs) > 2000:
            raise RuntimeError("too many switches (chattering?)")


def period_map(x, W, **params):
    """Exact state [q, q'](T), T = 2 pi / W, from x = [q, q'] at t = 0 (t = 0 mod T)."""
    return _flow(x, W, _p(params))[0]


def monodromy(x, W, **params):
    """Exact Jacobian of period_map: product of the regime transition matrices
    exp(A_r tau_i) (identity saltation matrices). Returns (x(T), M, number of switches)."""
    xT, segs, M = _flow(x, W, _p(params), jac=True)
    return xT, M, len(segs) - 1


def _extrema(segs, W, p):
    """(min q, max q) over one period from the closed forms: segment ends and q' = 0 roots."""
    Rs = (_regime(p, OPEN, W), _regime(p, CLOSED, W))
    lo, hi = np.inf, -np.inf
    for _, tau, r, cf in segs:
        R = Rs[r]
        n = max(1, int(math.ceil(tau / R["dt"])))
        tg, q, v = _qv_grid(R, cf, n)
        qe = _qv_scalar(R, cf, tau)[0]
        lo, hi = min(lo, q[0], qe), max(hi, q[0], qe)
        fv = lambda x, R=R, cf=cf: _qv_scalar(R, cf, x)[1]
        for kk in np.nonzero(v[:-1] * v[1:] <= 0)[0]:
            if tg[kk] >= tau:
                break
            b = min(tg[kk + 1], tau)
            if fv(tg[kk]) * fv(b) > 0:
                continue
            qx = _qv_scalar(R, cf, brentq(fv, tg[kk], b, **XT))[0]
            lo, hi = min(lo, qx), max(hi, qx)
    return lo, hi


def amplitude(x, W, **params):
    """Half peak-to-peak of q over one period from x at t = 0 (exact extrema)."""
    p = _p(params)
    lo, hi = _extrema(_flow(x, W, p)[1], W, p)
    return 0.5 * (hi - lo)


def linear_steady(W, **params):
    """Steady state [q, q'](0) of the contact-free (OPEN) regime."""
    R = _regime(_p(params), OPEN, W)
    return np.array([R["Q"], W * R["P"]])


# ---------------------------------------------------------------- marching sweeps
def _march(x, W, p, tol=1e-10, cap=5000, check=None):
    """Repeated period_map from x until |x_{k+1} - x_k| < tol (1 + |x_k|) or cap periods.
    check(x, k) -> True stops early.  Returns (x, periods, converged)."""
    x = np.asarray(x, float)
    for it in range(1, cap + 1):
        xn = _flow(x, W, p)[0]
        d = math.hypot(xn[0] - x[0], xn[1] - x[1])
        x = xn
        if d < tol * (1.0 + math.hypot(x[0], x[1])):
            return x, it, True
        if check is not None and check(x, it):
            return x, it, False
    return x, cap, False


def _amp(x, W, p):
    lo, hi = _extrema(_flow(x, W, p)[1], W, p)
    return 0.5 * (hi - lo)


def slow_sweep_jumps(
    direction,
    W_start=None,
    W_stop=None,
    dW_coarse=0.05,
    dW_fine=0.01,
    W_fine=(0.95, 1.5),
    cand_ratio=1.15,
    rel_tol=1e-6,
    settle_tol=1e-10,
    settle_cap=3000,
    bisect_cap=20000,
    verbose=False,
    **params,
):
    """Jump frequency of a slow stepped sweep (marching only, no continuation).

    direction "up": from rest at W_start (default 0.8), settled by marching, W stepped upward
    (dW_coarse outside W_fine, dW_fine inside); at each W march from the previous settled
    state until |x_{k+1} - x_k| < settle_tol (1 + |x|) or settle_cap periods, then record the
    amplitude (half peak-to-peak of q, exact).  "down": the same from rest at W_start
    (default 2.5), stepped downward.  A jump candidate is a step whose amplitude falls ("up")
    or rises ("down") by more than a factor cand_ratio; it is confirmed by the hysteresis
    itself: marching back at the previous W from the new state must settle on a second
    attractor (a steep but continuous branch returns to the old state instead).

    Refinement by bisection on [W_a (last on the old branch), W_b (first off)]: march from
    the old-branch state at W_a to W_mid; stop early once the amplitude has been closer to the
    post-jump amplitude A_b than to the old one A_a for 100 periods ("jumped"); if settled or
    after bisect_cap periods (critical slowing down), classify by amplitude (closer to A_a:
    "stayed", W_a = W_mid and its state becomes the new start), except that a cap hit with the
    drift per 25 periods growing over the last 100 periods is the far side of a ghost
    bottleneck ("jumped").  Until |W_b - W_a| < rel_tol W_a.

    A finite step can kick the state across the separatrix before the old branch ends (the
    saddle is close near a fold): the bracket's W_b is therefore verified at the end with a
    step < rel_tol from the state at W_a, and if the old branch survives there the sweep
    resumes from W_b with doubling steps (from rel_tol W_a) and bisects again.

    Returns dict(W_jump = (W_a + W_b)/2, W_a, W_b, x_a (old-branch state at W_a),
    amp_before (old branch, at W_a), amp_after (settled after the jump, at W_b),
    sweep (list of (W, amp, periods, converged)),
    trials (list of (kind, W, stayed, periods, converged, amp)),
    step_induced_jumps (number of repairs), periods (total), time_s)."""
    t0 = time.perf_counter()
    p = _p(params)
    up = {"up": True, "down": False}[direction]
    W = (0.8 if up else 2.5) if W_start is None else W_start
    W_stop = (2.5 if up else 0.5) if W_stop is None else W_stop
    sgn = 1.0 if up else -1.0
    x, n, conv = _march(np.zeros(2), W, p, settle_tol, 20 * settle_cap)
    A = _amp(x, W, p)
    sweep = [(W, A, n, conv)]
    total = n
    while True:
        inside = W_fine[0] <= W + sgn * dW_fine * 0.5 <= W_fine[1]
        Wn = W + sgn * (dW_fine if inside else dW_coarse)
        if (Wn - W_stop) * sgn > 0:
            raise RuntimeError("no jump found in the sweep range")
        xn, n, conv = _march(x, Wn, p, settle_tol, settle_cap)
        An = _amp(xn, Wn, p)
        total += n
        sweep.append((Wn, An, n, conv))
        if verbose:
            print(f"  sweep W={Wn:.5f} amp={An:.6f} periods={n} conv={conv}")
        if (An < A / cand_ratio) if up else (An > cand_ratio * A):
            # candidate jump: confirm the hysteresis by stepping back to W from the new state;
            # a genuine jump lands on a second attractor, distinct from the old one at W
            y, n, _ = _march(xn, W, p, settle_tol, settle_cap)
            total += n
            if np.abs(y - x).max() > 1e-4 * (1.0 + np.abs(x).max()):
                break
            if verbose:
                print(f"  (steep but continuous: back at W={W:.5f} the old state returns)")
        W, x, A = Wn, xn, An
    Wa, xa, Aa, Wb, Ab = W, x, A, Wn, An
    log, nrep = [], 0

    def trial(Wm, kind):
        """March from the settled old-branch state xa (at Wa) to Wm; classify by amplitude."""
        nonlocal total
        far = lambda a: abs(a - Ab) < abs(a - Aa)  # closer to the post-jump amplitude
        hist, snap, dist = [], [np.asarray(xa, float)], []

        def chk(y, k):
            if k % 25:
                return False
            hist.append(far(_amp(y, Wm, p)))
            dist.append(float(np.abs(y - snap[-1]).max()))
            snap.append(y)
            return len(hist) >= 4 and all(hist[-4:])  # 100 periods in a row on the far side

        y, n, conv = _march(xa, Wm, p, settle_tol, bisect_cap, chk)
        total += n
        Am = _amp(y, Wm, p)
        stayed = not far(Am)
        if stayed and not conv and n >= bisect_cap and len(dist) >= 5:
            # cap hit while still near the old branch: a drift that has been accelerating
            # over the last 100 periods is the far side of a ghost bottleneck (no orbit left)
            stayed = not (dist[-1] > dist[-2] > dist[-3] > dist[-4])
        log.append((kind, Wm, stayed, n, conv, Am))
        if verbose:
            print(f"  {kind} W={Wm:.10f} stayed={stayed} periods={n} conv={conv} amp={Am:.6f}")
        return stayed, y, conv, Am

    tiny = False  # W_b was last set by a step < 2 rel_tol from the current W_a state
    while True:
        while abs(Wb - Wa) > rel_tol * Wa:
            Wm = 0.5 * (Wa + Wb)
            stayed, y, conv, Am = trial(Wm, "bisect")
            if stayed:
                Wa, xa, Aa = Wm, y, (Am if conv else Aa)
                tiny = False
            else:
                Wb, yb, tiny = Wm, y, abs(Wm - Wa) < 2 * rel_tol * Wa
        if tiny:
            break
        # A finite step can kick the state over a nearby separatrix before the branch ends
        # (near the lower fold, which sits next to grazing, the basin is thin).  Verify W_b
        # with a step < rel_tol from the settled state at W_a; if it stays, the earlier jump
        # was step-induced: resume the sweep from W_b with doubling steps and bisect again.
        stayed, y, conv, Am = trial(Wb, "verify")
        if not stayed:
            yb = y
            break
        nrep += 1
        Wa, xa, Aa = Wb, y, (Am if conv else Aa)
        h = rel_tol * Wa
        while True:
            Wn = Wa + sgn * h
            stayed, y, conv, Am = trial(Wn, "resume")
            if not stayed:
                Wb, yb = Wn, y
                break
            Wa, xa, Aa = Wn, y, (Am if conv else Aa)
            h *= 2.0
    # the post-jump state at W_b, settled (amplitude after the jump)
    yb, n, _ = _march(yb, Wb, p, settle_tol, 20 * settle_cap)
    total += n
    return dict(
        W_jump=0.5 * (Wa + Wb),
        W_a=Wa,
        W_b=Wb,
        x_a=xa,
        amp_before=_amp(xa, Wa, p),
        amp_after=_amp(yb, Wb, p),
        sweep=sweep,
        trials=log,
        step_induced_jumps=nrep,
        periods=total,
        time_s=time.perf_counter() - t0,
    )


# ---------------------------------------------------------------- continuation (cross-check)
def periodic_orbit(W, x_guess=None, tol=1e-12, maxit=40, **params):
    """Newton shooting on period_map(x) - x = 0 with the exact monodromy.
    Returns dict(x, mu (Floquet multipliers), converged, iterations, nswitch, amp)."""
    p = _p(params)
    x = linear_steady(W, **params) if x_guess is None else np.array(x_guess, float)
    for it in range(maxit + 1):
        xT, segs, M = _flow(x, W, p, jac=True)
        R = xT - x
        if np.linalg.norm(R) < tol * (1 + np.linalg.norm(x)) or it == maxit:
            break
        x = x + np.linalg.solve(M - np.eye(2), -R)
    conv = bool(np.linalg.norm(R) < tol * (1 + np.linalg.norm(x)))
    lo, hi = _extrema(segs, W, p)
    return dict(x=x, mu=np.linalg.eigvals(M), converged=conv, iterations=it,
                nswitch=len(segs) - 1, amp=0.5 * (hi - lo), max_q=hi)


def _RJ(y, p):
    """Residual period_map(x, W) - x and its 2x3 Jacobian [M - I, dP/dW] (dP/dW: central
    differences, h = 1e-6 W; only steers Newton, the converged point depends on R alone)."""
    W = y[2]
    xT, segs, M = _flow(y[:2], W, p, jac=True)
    h = 1e-6 * W
    dW = (_flow(y[:2], W + h, p)[0] - _flow(y[:2], W - h, p)[0]) / (2 * h)
    return xT - y[:2], np.column_stack([M - np.eye(2), dW]), M, segs


def _tangent(J, tref):
    t = np.linalg.solve(np.vstack([J, tref]), np.array([0.0, 0.0, 1.0]))
    return t / np.linalg.norm(t)


def _correct(y_pred, t, p, tol=1e-12, maxit=12, dymax=0.3):
    """Pseudo-arclength corrector on the hyperplane t . (y - y_pred) = 0."""
    y = y_pred.copy()
    for it in range(maxit + 1):
        R, J, M, segs = _RJ(y, p)
        if np.linalg.norm(R) < tol * (1 + np.linalg.norm(y[:2])) and abs(t @ (y - y_pred)) < tol:
            return y, J, M, segs, it
        if it == maxit:
            return None
        dy = np.linalg.solve(np.vstack([J, t]), -np.append(R, t @ (y - y_pred)))
        if np.linalg.norm(dy) > dymax or y[2] + dy[2] <= 0.05:
            return None
        y = y + dy


def _pt(y, J, M, segs, tref, p):
    lo, hi = _extrema(segs, y[2], p)
    mu = np.linalg.eigvals(M)
    return dict(y=y, t=_tangent(J, tref), mu=mu, mu_max=np.abs(mu).max(),
                mu1=np.sort(mu.real)[-1] if np.isreal(mu).all() else np.nan,
                detMI=np.linalg.det(M - np.eye(2)), amp=0.5 * (hi - lo), max_q=hi,
                nswitch=len(segs) - 1)


def _on_branch(P, sig, p):
    c = _correct(P["y"] + sig * P["t"], P["t"], p, maxit=30, dymax=np.inf)
    if c is None:
        raise RuntimeError("corrector failed during refinement")
    return _pt(*c[:4], P["t"], p)


def continuation(W_start=0.8, W_end=1.6, ds0=0.01, ds_min=1e-10, ds_max=0.04,
                 cos_max=0.995, ds_angle_free=1e-4, max_steps=4000, **params):
    """Pseudo-arclength continuation of the fixed point of period_map in y = (q0, q0', W),
    from the contact-free orbit at W_start towards increasing W, until W_end.
    Folds: sign change of dW/ds, refined twice on the branch (sig = arclength parameter of
    the hyperplane through the last point before the fold): (i) extremum of W(sig) by bounded
    Brent, (ii) det(M - I) = 0 (a real multiplier through +1) by brentq.
    Grazing (max q = g) and stability changes (max |mu| = 1) refined by brentq as well."""
    t0 = time.perf_counter()
    p = _p(params)
    po = periodic_orbit(W_start, **params)
    assert po["converged"]
    y = np.append(po["x"], W_start)
    R, J, M, segs = _RJ(y, p)
    pts = [_pt(y, J, M, segs, np.array([0.0, 0.0, 1.0]), p)]
    ds, nrej = ds0, 0
    for _ in range(max_steps):
        P = pts[-1]
        c = _correct(P["y"] + ds * P["t"], P["t"], p)
        Q = None if c is None else _pt(*c[:4], P["t"], p)
        if Q is None or (Q["t"] @ P["t"] < cos_max and ds > ds_angle_free):
            ds *= 0.5
            nrej += 1
            if ds < ds_min:
                raise RuntimeError(f"step size underflow at W = {P['y'][2]}")
            continue
        P["ds"] = ds
        pts.append(Q)
        if Q["y"][2] >= W_end:
            break
        ds = float(np.clip(ds * (1.5 if c[4] <= 2 else (1.0 if c[4] <= 4 else 0.6)),
                           ds_min, ds_max))
    folds, graz, stab = [], [], []
    for k in range(len(pts) - 1):
        P, Q = pts[k], pts[k + 1]
        if P["t"][2] * Q["t"][2] < 0:
            sgn = 1.0 if P["t"][2] > 0 else -1.0  # W has a max (upper fold) or a min
            r = minimize_scalar(lambda s, P=P, sgn=sgn: -sgn * _on_branch(P, s, p)["y"][2],
                                bounds=(0.0, P["ds"]), method="bounded",
                                options=dict(xatol=1e-12))
            F = _on_branch(P, r.x, p)
            s1 = brentq(lambda s, P=P: _on_branch(P, s, p)["detMI"], 0.0, P["ds"], xtol=1e-15)
            F1 = _on_branch(P, s1, p)
            folds.append(dict(W=F["y"][2], W_detMI=F1["y"][2], amp=F["amp"], mu=F["mu"],
                              mu_detMI=F1["mu"], kind="max W" if sgn > 0 else "min W",
                              max_q=F["max_q"], index=k, x=F["y"][:2]))
        if (P["max_q"] - p[5]) * (Q["max_q"] - p[5]) < 0:
            s1 = brentq(lambda s, P=P: _on_branch(P, s, p)["max_q"] - p[5], 0.0, P["ds"],
                        xtol=1e-14)
            G = _on_branch(P, s1, p)
            graz.append(dict(W=G["y"][2], amp=G["amp"], index=k))
        if (P["mu_max"] - 1) * (Q["mu_max"] - 1) < 0:
            s1 = brentq(lambda s, P=P: _on_branch(P, s, p)["mu_max"] - 1, 0.0, P["ds"],
                        xtol=1e-14)
            S = _on_branch(P, s1, p)
            stab.append(dict(W=S["y"][2], mu=S["mu"], amp=S["amp"], index=k,
                             change="loses" if P["mu_max"] < 1 else "gains"))
    arr = lambda key: np.array([q[key] for q in pts])
    return dict(W=arr("y")[:, 2], x=arr("y")[:, :2], amp=arr("amp"), mu_max=arr("mu_max"),
                mu=arr("mu"), max_q=arr("max_q"), nswitch=arr("nswitch"), folds=folds,
                grazing=graz, stability_changes=stab, n_points=len(pts), n_rejected=nrej,
                time_s=time.perf_counter() - t0)


# ---------------------------------------------------------------- validation
def period_map_ivp(x, W, rtol=1e-12, atol=1e-14, **params):
    """Independent check of period_map: DOP853 restarted at every event q = g."""
    from scipy.integrate import solve_ivp

    m, k, c, F0, kc, g = _p(params)
    T = 2 * np.pi / W
    t, y, r = 0.0, np.array(x, float), _regime0(x, g)
    nsw = 0
    while True:

        def f(tt, yy, r=r):
            fnl = kc * (yy[0] - g) if r == CLOSED else 0.0
            return [yy[1], (F0 * np.sin(W * tt) - c * yy[1] - k * yy[0] - fnl) / m]

        ev = lambda tt, yy: yy[0] - g
        ev.terminal, ev.direction = True, (1 if r == OPEN else -1)
        sol = solve_ivp(f, (t, T), y, method="DOP853", rtol=rtol, atol=atol, events=ev)
        y = sol.y[:, -1]
        if sol.status != 1:
            return y, nsw
        t, r, nsw = sol.t[-1], 1 - r, nsw + 1
        y[0] = g


def _expm_check(W, p):
    """Closed form of each regime vs scipy expm of the augmented 5x5 system
    z = [q, q', sin Wt, cos Wt, 1], z' = L z (max abs difference over a few (tau, start))."""
    from scipy.linalg import expm

    m, k, c, F0, kc, g = p
    err = 0.0
    for r in (OPEN, CLOSED):
        L = np.zeros((5, 5))
        L[0, 1] = 1.0
        L[1, 0], L[1, 1], L[1, 2], L[1, 4] = -(k + r * kc) / m, -c / m, F0 / m, r * kc * g / m
        L[2, 3], L[3, 2] = W, -W
        R = _regime(p, r, W)
        for ta, tau, x in ((0.3, 0.7, (0.9, -0.4)), (2.0, 3.1, (-1.2, 0.8)), (0.0, 5.0, (0.1, 2))):
            z = np.array([x[0], x[1], np.sin(W * ta), np.cos(W * ta), 1.0])
            ze = expm(L * tau) @ z
            qv = _qv_scalar(R, _coef(R, ta, *x), tau)
            err = max(err, np.abs(np.array(qv) - ze[:2]).max())
    return err


def _branch_stability(x, W, p, dWs, sgn):
    """Multipliers of the stable orbit at W - sgn dW for the distances dWs from a fold at W,
    reached by marching (settles on the attractor) from the fold-side state x, then Newton."""
    out = []
    for dW in dWs:
        Wd = W - sgn * dW
        y = _march(x, Wd, p, 1e-11, 200000)[0]
        po = periodic_orbit(Wd, y, **dict(zip(("m", "k", "c", "F0", "k_c", "g"), p)))
        out.append((dW, Wd, po["mu"], po["amp"], po["converged"]))
    return out


def validate(verbose=True, **params):
    """(a) period_map vs DOP853 with events; closed form vs expm; monodromy vs central
    differences; exact amplitude vs dense sampling.  (b) folds by continuation (extremum of W
    and det(M - I) = 0) vs the jumps of the marching sweeps.  (c) Floquet multipliers along
    the branches, up to each fold.  Returns a dict of the figures (and prints them)."""
    p = _p(params)
    pr = print if verbose else (lambda *a, **k: None)
    res = {}
    # ---- (a) the exact period map
    po12 = periodic_orbit(1.2, [-1.5, -0.3], **params)  # upper (resonant) branch, contact
    cases = [(po12["x"], 1.2), (np.array([1.3, 0.4]), 1.0), (np.array([0.2, -0.9]), 1.05),
             (np.array([-0.4, 3.0]), 2.3)]
    e_ivp, nsw = 0.0, []
    for x, W in cases:
        xe, ns = period_map_ivp(x, W, **params)
        e_ivp = max(e_ivp, np.abs(period_map(x, W, **params) - xe).max() / np.abs(xe).max())
        nsw.append(ns)
    e_fd = 0.0
    for x, W in cases:
        M = monodromy(x, W, **params)[1]
        h = 1e-6
        fd = np.column_stack([(period_map(x + h * e, W, **params)
                               - period_map(x - h * e, W, **params)) / (2 * h)
                              for e in np.eye(2)])
        e_fd = max(e_fd, np.abs(fd - M).max() / np.abs(M).max())
    e_exp = max(_expm_check(W, p) for W in (0.9, 1.25, 2.0))
    x, W = cases[0]
    segs = _flow(x, W, p)[1]
    ts = np.linspace(0, 2 * np.pi / W, 20001)
    qs = []
    Rs = (_regime(p, OPEN, W), _regime(p, CLOSED, W))
    for t in ts:
        for ta, tau, r, cf in segs:
            if ta <= t <= ta + tau:
                qs.append(_qv_scalar(Rs[r], cf, t - ta)[0])
                break
    e_amp = amplitude(x, W, **params) - 0.5 * (max(qs) - min(qs))
    res.update(ivp_rel_err=e_ivp, ivp_switches=nsw, monodromy_fd_rel_err=e_fd,
               closed_form_vs_expm=e_exp, amp_exact_minus_sampled=e_amp,
               orbit_1p2=(po12["amp"], po12["mu"]))
    pr(f"(a) period_map vs DOP853 (rtol 1e-12, atol 1e-14, events q = g): max rel err "
       f"{e_ivp:.2e}  (switches per period: {nsw})")
    pr(f"    closed form vs expm(augmented 5x5): {e_exp:.2e};  monodromy vs central "
       f"differences: {e_fd:.2e};  exact - sampled (20001) amplitude: {e_amp:.2e}")
    # ---- (b) folds by continuation vs jumps by marching
    t0 = time.perf_counter()
    cont = continuation(**params)
    t_cont = time.perf_counter() - t0
    folds = sorted(cont["folds"], key=lambda f: f["W"])
    pr(f"(b) continuation: {cont['n_points']} points, {cont['n_rejected']} rejected steps, "
       f"{t_cont:.2f} s")
    for f in folds:
        pr(f"    fold ({f['kind']}): W = {f['W']:.10f} (extremum of W), {f['W_detMI']:.10f} "
           f"(det(M - I) = 0), amp = {f['amp']:.8f}, max q - g = {f['max_q'] - p[5]:.3e}, "
           f"mu = {np.round(f['mu'], 8)}")
    for gz in cont["grazing"]:
        pr(f"    grazing (max q = g): W = {gz['W']:.10f}")
    for s in cont["stability_changes"]:
        pr(f"    stability {s['change']} at W = {s['W']:.10f}, mu = {np.round(s['mu'], 8)}")
    jumps = {}
    for d in ("up", "down"):
        jumps[d] = slow_sweep_jumps(d, **params)
    t_up, t_dn = jumps["up"]["time_s"], jumps["down"]["time_s"]
    Wl, Wu = folds[0]["W"], folds[-1]["W"]
    ju, jd = jumps["up"], jumps["down"]
    pr(f"    sweep up  : jump at W = {ju['W_jump']:.10f} (bracket [{ju['W_a']:.10f}, "
       f"{ju['W_b']:.10f}]), amp {ju['amp_before']:.6f} -> {ju['amp_after']:.6f}, "
       f"{ju['periods']} periods, {t_up:.2f} s;  jump - upper fold = {ju['W_jump'] - Wu:.2e}")
    pr(f"    sweep down: jump at W = {jd['W_jump']:.10f} (bracket [{jd['W_b']:.10f}, "
       f"{jd['W_a']:.10f}]), amp {jd['amp_before']:.6f} -> {jd['amp_after']:.6f}, "
       f"{jd['periods']} periods, {t_dn:.2f} s, step-induced early jumps repaired: "
       f"{jd['step_induced_jumps']};  jump - lower fold = {jd['W_jump'] - Wl:.2e}")
    res.update(fold_lower=Wl, fold_upper=Wu, jump_up=ju["W_jump"], jump_down=jd["W_jump"],
               fold_lower_detMI=folds[0]["W_detMI"], fold_upper_detMI=folds[-1]["W_detMI"],
               fold_in_bracket_up=min(ju["W_a"], ju["W_b"]) <= Wu <= max(ju["W_a"], ju["W_b"]),
               fold_in_bracket_down=min(jd["W_a"], jd["W_b"]) <= Wl
               <= max(jd["W_a"], jd["W_b"]),
               time_up=t_up, time_down=t_dn, continuation=cont, jumps=jumps)
    # ---- (c) stability along the branches
    iu = folds[-1]["index"]  # continuation index just before the upper fold
    il = folds[0]["index"]
    up_part = slice(0, iu + 1)  # start -> upper fold (resonant branch)
    lo_part = slice(il + 1, None)  # lower fold -> end (non-resonant branch)
    mid_part = slice(iu + 1, il + 1)
    mu = cont["mu"]
    neg = lambda sl: bool((np.isreal(mu[sl]) & (mu[sl].real < 0)).any())
    res.update(
        upper_branch_mu_max=cont["mu_max"][up_part].max(),
        lower_branch_mu_max=cont["mu_max"][lo_part].max(),
        middle_branch_mu_max_min=cont["mu_max"][mid_part].min(),
        negative_real_multiplier=neg(slice(None)),
    )
    pr(f"(c) max |mu| on the resonant branch W in [{cont['W'][0]:.2f}, upper fold): "
       f"{res['upper_branch_mu_max']:.6f};  on the non-resonant branch (lower fold, "
       f"{cont['W'][-1]:.2f}]: {res['lower_branch_mu_max']:.6f};  min over the middle "
       f"(saddle) branch: {res['middle_branch_mu_max_min']:.6f};  a negative real "
       f"multiplier anywhere (flip): {res['negative_real_multiplier']}")
    near = {}
    dWs = (1e-3, 1e-4, 1e-5, 1e-6, 2e-7)
    near["upper"] = _branch_stability(_settled_near(ju, p), Wu, p, dWs, 1.0)
    near["lower"] = _branch_stability(_settled_near(jd, p), Wl, p, dWs, -1.0)
    for key in ("upper", "lower"):
        for dW, Wd, m_, a_, _conv in near[key]:
            pr(f"    {key} fold {'-' if key == 'upper' else '+'} {dW:.0e} (W = {Wd:.8f}, "
               f"from the sweep's state): amp = {a_:.6f}, mu = {np.round(m_, 6)}, "
               f"|mu|max = {np.abs(m_).max():.6f}")
    res["near_fold"] = near
    return res


def _settled_near(j, p):
    """Settled old-branch state at the sweep's W_a (re-marched from its last stayed trial)."""
    W = j["W_a"]
    x = j["x_a"]
    return _march(x, W, p, 1e-11, 200000)[0]


if __name__ == "__main__":
    t0 = time.perf_counter()
    v = validate()
    print(f"total {time.perf_counter() - t0:.1f} s")
