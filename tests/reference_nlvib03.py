"""Exact piecewise-linear reference for NLvib example 03 (2-DOF chain, unilateral spring).

numpy/scipy only; nothing here imports absorber_jax.

System, q = [q1, q2], x = [q, q'] :
    M q'' + D q' + K q + f_nl(q1) = F(t),   M = I,  K = [[1, -1], [-1, 2]],  D = 0.03 K,
    F(t) = [0, 0.1 sin(W t)],               f_nl = 100 (q1 - 1) if q1 > 1 else 0.
Two linear regimes r (OPEN: q1 <= 1, CLOSED: q1 > 1):
    x' = A_r x + b_r + g sin(W t),  A_r = [[0, I], [-K_r, -D]],  K_r = K + 100 r e1 e1^T,
    b_r = [0, 0, 100 r, 0],  g = [0, 0, 0, 0.1].
Exact solution inside a regime: augment with the forcing generator, z = [x, sin Wt, cos Wt, 1],
z' = L_r z, so z(t_a + tau) = expm(L_r tau) z(t_a) (and the same in eigen form,
z(t_a + tau) = V e^{Lambda tau} V^-1 z(t_a), used to scan/root-find q1(t) - 1 cheaply).
Switches (q1 = 1) are bracketed on a grid of 1/40 of the fastest closed-regime natural period
(grazing double crossings caught through sign changes of q1') and located by brentq (~1e-15 rel).

Saltation: at a switch the vector field is continuous (the spring force 100 (q1 - 1) vanishes
on q1 = 1), so S = I + (f+ - f-) n^T / (n^T f-) = I; the period-map Jacobian is the plain
product of the regime transition matrices expm(A_r tau_i) (checked against central finite
differences of period_map in `validate`, agreement ~1e-9).  The same holds for the parameter
sensitivity dx/dW, carried exactly in the 13-dim augmented state of `_aug13`.
The state itself is propagated with the eigen form (mpmath check: ~1e-14; expm ~1e-13 on long
closed arcs); the Jacobians with expm.  Fundamental harmonics and the energy integrals are
integrated exactly too (augmented linear systems / Van Loan), not sampled.

Grazing (max q1 = 1): the flow is C1 but its Jacobian varies like sqrt(distance to grazing),
so along the branch the multipliers and the tangent change abruptly there (e.g. the lower fold
sits ~6e-9 in Omega from the grazing point where contact starts).

Results of `python tests/reference_nlvib03.py` (continuation 0.8 -> 0.5, ~2 s):
    peak |Q2| = 0.9363056809 at Omega = 0.7511845596 (inside the flip-unstable window)
    turning points (Omega, |Q2|): (0.6534401345, 0.5732413726), (0.7556273526, 0.8957684886)
    grazing: contact starts at Omega = 0.6534401404, ends at 0.5818996390
    stability: loses at fold 0.6534401345 (mu=+1), gains at fold 0.7556273526 (mu=+1),
        loses at flip 0.7555861594 (mu=-1), gains at flip 0.7387830254 (mu=-1),
        loses at Neimark-Sacker 0.6186068743 (mu = -0.0698 + 0.9976i),
        gains at Neimark-Sacker 0.5819006504 (mu = 0.5781 + 0.8159i)
"""

import os
import sys
import time
from functools import lru_cache

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # tiny matrices: threaded BLAS is ~40x slower
import numpy as np  # noqa: E402
from scipy.linalg import eig, expm, solve  # noqa: E402
from scipy.optimize import brentq, minimize_scalar  # noqa: E402

K = np.array([[1.0, -1.0], [-1.0, 2.0]])
D = 0.03 * K
F_AMP, GAP, K_NL = 0.1, 1.0, 100.0
OPEN, CLOSED = 0, 1
G = np.array([0.0, 0.0, 0.0, F_AMP])
XT = dict(xtol=1e-15, rtol=4 * np.finfo(float).eps, maxiter=200)  # brentq tolerances


def _AB(r):
    """A_r, b_r of x' = A_r x + b_r + g sin(Wt) in regime r."""
    Kr = K + (K_NL * np.diag([1.0, 0.0]) if r == CLOSED else 0.0)
    A = np.block([[np.zeros((2, 2)), np.eye(2)], [-Kr, -D]])
    b = np.array([0.0, 0.0, K_NL * GAP if r == CLOSED else 0.0, 0.0])
    return A, b


# grid for bracketing switches: 1/40 of the fastest natural period of the closed regime
DT = 2 * np.pi / np.abs(np.linalg.eigvals(_AB(CLOSED)[0]).imag).max() / 40

# 13-dim augmented state Z = [x(4), s = dx/dW at fixed t (4), sin, cos, t sin, t cos, 1]
iS, iC, iTS, iTC, i1 = 8, 9, 10, 11, 12
I7 = [0, 1, 2, 3, iS, iC, i1]  # closed sub-system z = [x, sin, cos, 1]


@lru_cache(maxsize=64)
def _aug13(r, Om):
    """Z' = L Z:  x' = A x + g sin + b;  s' = A s + g t cos(Wt)  (= d/dW of the forcing);
    (sin)' = W cos, (cos)' = -W sin, (t sin)' = sin + W t cos, (t cos)' = cos - W t sin."""
    A, b = _AB(r)
    L = np.zeros((13, 13))
    L[:4, :4], L[:4, iS], L[:4, i1] = A, G, b
    L[4:8, 4:8], L[4:8, iTC] = A, G
    L[iS, iC], L[iC, iS] = Om, -Om
    L[iTS, iS], L[iTS, iTC] = 1.0, Om
    L[iTC, iC], L[iTC, iTS] = 1.0, -Om
    return L


@lru_cache(maxsize=64)
def _eig7(r, Om):
    """Eigen form of the 7-dim sub-system z = [x, sin, cos, 1]: z(tau) = V e^{lam tau} V^-1 z0."""
    lam, V = eig(_aug13(r, Om)[np.ix_(I7, I7)])
    return lam, V, np.linalg.inv(V)


def _xeval(r, Om, z7, tau, rows=(0, 2)):
    """Closed-form components `rows` of x(t_a + tau) (tau scalar or array)."""
    lam, V, Vi = _eig7(r, Om)
    E = np.exp(np.multiply.outer(np.asarray(tau, float), lam)) * (Vi @ z7)
    X = (E @ V[list(rows)].T).real
    return [X[..., j] for j in range(len(rows))]


def _next_event(r, Om, z7, span):
    """First switch time tau in (0, span] of regime r starting from z7, or (span, False).
    Leaving the regime: OPEN -> q1 - 1 > 0, CLOSED -> q1 - 1 < 0 (sigma = +1 / -1)."""
    sg = 1.0 if r == OPEN else -1.0
    tau = np.linspace(0.0, span, max(2, int(np.ceil(span / DT)) + 1))
    q, v = _xeval(r, Om, z7, tau)
    q = q - GAP
    fq = lambda s: float(_xeval(r, Om, z7, s)[0]) - GAP
    fv = lambda s: float(_xeval(r, Om, z7, s)[1])
    out = sg * q[1:] > 0  # sample 0 is in the regime by definition (it may be a switch point)
    kout = int(np.argmax(out)) + 1 if out.any() else None
    # grazing: an extremum of q1 towards the boundary inside one subdivision, q1 beyond it
    for k in np.nonzero((sg * v[:-1] > 0) & (sg * v[1:] <= 0))[0] + 1:
        if kout is not None and k >= kout:
            break
        ts = brentq(fv, tau[k - 1], tau[k], **XT)
        if sg * fq(ts) > 0:
            return brentq(fq, tau[k - 1], ts, **XT), True
    if kout is None:
        return span, False
    lo = tau[kout - 1]
    if kout == 1 and sg * v[0] < 0 < sg * v[1]:  # re-exit within the first subdivision
        lo = brentq(fv, 0.0, tau[1], **XT)  # start the bracket at the interior extremum
    return brentq(fq, lo, tau[kout], **XT), True


def _regime0(x0):
    return CLOSED if x0[0] > GAP or (x0[0] == GAP and x0[2] > 0) else OPEN


def _trajectory(x0, Om):
    """Exact flow over [0, T]: (Z(T), dZ(T)/dZ(0), segments [(t_a, tau, r, Z(t_a))], last r)."""
    T = 2 * np.pi / Om
    Z = np.zeros(13)
    Z[:4], Z[iC], Z[i1] = x0, 1.0, 1.0
    r, t, Phi, segs = _regime0(x0), 0.0, np.eye(13), []
    while True:
        tau, hit = _next_event(r, Om, Z[I7], T - t)
        E = expm(_aug13(r, Om) * tau)
        segs.append((t, tau, r, Z.copy()))
        xe = np.array(_xeval(r, Om, Z[I7], tau, rows=range(4)))
        Z, Phi = E @ Z, E @ Phi  # saltation = identity (continuous vector field)
        # the state itself from the eigen form: ~1e-14 vs mpmath (expm ~1e-13 on long closed arcs)
        Z[:4] = xe
        if not hit:
            return Z, Phi, segs, r
        t, r = t + tau, 1 - r
        if len(segs) > 10000:
            raise RuntimeError("too many switches (chattering?)")


def shoot(x0, Om):
    """x(T), monodromy dx(T)/dx0 and dx(T)/dW of the period map, T = 2 pi / W.
    dx(T)/dW = s(T) + x'(T) dT/dW, dT/dW = -T/W (switch times move, but f is continuous)."""
    x0 = np.asarray(x0, float)
    Z, Phi, segs, r = _trajectory(x0, Om)
    xdot = (_aug13(r, Om) @ Z)[:4]
    return dict(
        xT=Z[:4].copy(),
        mon=Phi[:4, :4].copy(),
        dOm=Z[4:8] - xdot * 2 * np.pi / Om**2,
        segs=segs,
        nswitch=len(segs) - 1,
    )


def period_map(x0, Omega):
    """Exact state x(T) after one forcing period T = 2 pi / Omega, starting at t = 0."""
    return shoot(x0, Omega)["xT"]


def monodromy(x0, Omega):
    """4x4 Jacobian of period_map: prod_i expm(A_{r_i} tau_i) (identity saltation matrices)."""
    return shoot(x0, Omega)["mon"]


def linear_frf(Omega):
    """Open-regime (linear) harmonic response: Q = (K - W^2 M + i W D)^-1 [0, 0.1],
    q(t) = Im(Q e^{iWt}); returns (Q, x0 = [Im Q, W Re Q])."""
    Q = solve(K - Omega**2 * np.eye(2) + 1j * Omega * D, np.array([0.0, F_AMP]))
    return Q, np.concatenate([Q.imag, Omega * Q.real])


def periodic_orbit(Omega, x_guess=None, tol=1e-12, maxit=40):
    """Newton shooting on R(x) = period_map(x) - x, (Mon - I) dx = -R.
    Returns dict(x0, multipliers, mu_max, converged, iterations, residual)."""
    x = linear_frf(Omega)[1] if x_guess is None else np.array(x_guess, float)
    for it in range(maxit + 1):
        s = shoot(x, Omega)
        R = s["xT"] - x
        if np.linalg.norm(R) < tol * (1 + np.linalg.norm(x)):
            break
        if it == maxit:
            break
        x = x + solve(s["mon"] - np.eye(4), -R)
    mu = np.linalg.eigvals(s["mon"])
    res = np.linalg.norm(R)
    return dict(
        x0=x,
        multipliers=mu,
        mu_max=np.abs(mu).max(),
        converged=bool(res < tol * (1 + np.linalg.norm(x))),
        iterations=it,
        residual=res,
        nswitch=s["nswitch"],
    )


# ---------------------------------------------------------------- harmonics / sampling / energy
def _aug25(r, Om):
    """Exact Fourier integrals: H = [x, yc = x cos, ys = x sin, Jc = int yc, Js = int ys,
    sin, cos, sin2, cos2, 1];  yc' = A yc + g sin2/2 + b cos - W ys,
    ys' = A ys + g (1 - cos2)/2 + b sin + W yc  (sin cos = sin2/2, sin^2 = (1 - cos2)/2)."""
    A, b = _AB(r)
    I4, L = np.eye(4), np.zeros((25, 25))
    L[:4, :4], L[:4, 20], L[:4, 24] = A, G, b
    L[4:8, 4:8], L[4:8, 22], L[4:8, 21], L[4:8, 8:12] = A, G / 2, b, -Om * I4
    L[8:12, 8:12], L[8:12, 24], L[8:12, 23], L[8:12, 20], L[8:12, 4:8] = (
        A,
        G / 2,
        -G / 2,
        b,
        Om * I4,
    )
    L[12:16, 4:8], L[16:20, 8:12] = I4, I4
    L[20, 21], L[21, 20], L[22, 23], L[23, 22] = Om, -Om, 2 * Om, -2 * Om
    return L


def _max_q1(segs, Om):
    """max q1 over the orbit: grid + brentq on q1' = 0 (q1' from + to -) in every segment."""
    best = -np.inf
    for _, tau, r, Z in segs:
        z7 = Z[I7]
        g = np.linspace(0.0, tau, max(2, int(np.ceil(tau / DT)) + 1))
        q, v = _xeval(r, Om, z7, g)
        best = max(best, q.max())
        fv = lambda s, r=r, z7=z7: float(_xeval(r, Om, z7, s)[1])
        for k in np.nonzero((v[:-1] > 0) & (v[1:] <= 0))[0]:
            ts = brentq(fv, g[k], g[k + 1], **XT)
            best = max(best, float(_xeval(r, Om, z7, ts)[0]))
    return best


def harmonic_amplitudes(x0, Omega, segs=None):
    """Fundamental harmonic by exact integration, Qhat = (2/T) int_0^T x e^{-iWt} dt
    (so x ~ Re(Qhat e^{iWt})), and max q1.
    Returns dict(Q1, Q2 = |Qhat| of q1, q2, Qhat (4 complex, for x), max_q1)."""
    if segs is None:
        segs = shoot(x0, Omega)["segs"]
    H = np.zeros(25)
    H[:4] = H[4:8] = x0
    H[21] = H[23] = H[24] = 1.0
    for _, tau, r, _Z in segs:
        H = expm(_aug25(r, Omega) * tau) @ H
    Qh = (H[12:16] - 1j * H[16:20]) * Omega / np.pi
    return dict(Q1=abs(Qh[0]), Q2=abs(Qh[1]), Qhat=Qh, max_q1=_max_q1(segs, Omega))


def sample_orbit(x0, Omega, n=4096):
    """x at t_j = j T / n, j = 0..n-1, from the closed form of each segment."""
    segs = shoot(x0, Omega)["segs"]
    t = np.arange(n) * (2 * np.pi / Omega / n)
    X = np.empty((n, 4))
    for t_a, tau, r, Z in segs:
        sel = (t >= t_a) & (t <= t_a + tau)
        if sel.any():
            X[sel] = np.array(_xeval(r, Omega, Z[I7], t[sel] - t_a, rows=range(4))).T
    return t, X


def energy_balance(x0, Omega):
    """Exact E_in = int F . q' dt and E_diss = int q'^T D q' dt over [0, T] (Van Loan:
    int_0^h e^{L^T s} Q e^{L s} ds = E22^T E12 with E = expm([[-L^T, Q], [0, L]] h))."""
    Qin, Qd = np.zeros((13, 13)), np.zeros((13, 13))
    Qin[3, iS] = Qin[iS, 3] = F_AMP / 2
    Qd[2:4, 2:4] = D
    out = []
    for Q in (Qin, Qd):
        e = 0.0
        for _, tau, r, Z in shoot(x0, Omega)["segs"]:
            L = _aug13(r, Omega)
            E = expm(np.block([[-L.T, Q], [np.zeros((13, 13)), L]]) * tau)
            e += Z @ (E[13:, 13:].T @ E[:13, 13:]) @ Z
        out.append(e)
    return tuple(out)


def period_map_ivp(x0, Omega, rtol=1e-12, atol=1e-14):
    """Independent check of period_map: DOP853, restarted at every switch event q1 = 1."""
    from scipy.integrate import solve_ivp

    T = 2 * np.pi / Omega
    t, x, r = 0.0, np.array(x0, float), _regime0(x0)
    while True:

        def f(tt, xx, r=r):
            A, b = _AB(r)
            return A @ xx + b + G * np.sin(Omega * tt)

        ev = lambda tt, xx: xx[0] - GAP
        ev.terminal, ev.direction = True, (1 if r == OPEN else -1)
        sol = solve_ivp(f, (t, T), x, method="DOP853", rtol=rtol, atol=atol, events=ev)
        x = sol.y[:, -1]
        if sol.status != 1:
            return x
        t, r = sol.t[-1], 1 - r


# ---------------------------------------------------------------- continuation
def _RJ(y):
    s = shoot(y[:4], y[4])
    return s["xT"] - y[:4], np.hstack([s["mon"] - np.eye(4), s["dOm"][:, None]]), s


def _tangent(J, tref):
    """Null vector of J (4x5), oriented by tref: [J; tref^T] t = e5, normalised."""
    t = solve(np.vstack([J, tref]), np.eye(5)[4])
    return t / np.linalg.norm(t)


def _correct(y_pred, t, tol=1e-12, maxit=10, dymax=0.5):
    """Pseudo-arclength Newton: R(y) = 0, t . (y - y_pred) = 0.
    Returns (y, J, shoot dict, Newton iterations) or None."""
    y = y_pred.copy()
    for it in range(maxit + 1):
        R, J, s = _RJ(y)
        if np.linalg.norm(R) < tol * (1 + np.linalg.norm(y[:4])) and abs(t @ (y - y_pred)) < tol:
            return y, J, s, it
        if it == maxit:
            return None
        dy = solve(np.vstack([J, t]), -np.append(R, t @ (y - y_pred)))
        if np.linalg.norm(dy) > dymax or y[4] + dy[4] <= 0.05:
            return None
        y = y + dy


def _point(y, J, s, tref, nfev):
    mu = np.linalg.eigvals(s["mon"])
    h = harmonic_amplitudes(y[:4], y[4], s["segs"])
    return dict(
        y=y,
        t=_tangent(J, tref),
        mu=mu,
        mu_max=np.abs(mu).max(),
        Q1=h["Q1"],
        Q2=h["Q2"],
        max_q1=h["max_q1"],
        nswitch=s["nswitch"],
        nfev=nfev,
    )


def _on_branch(P, sig):
    """Branch point at arclength-parameter sig from accepted point P (predictor P.y + sig P.t,
    corrector on the hyperplane orthogonal to P.t)."""
    c = _correct(P["y"] + sig * P["t"], P["t"], maxit=20, dymax=np.inf)
    if c is None:
        raise RuntimeError("corrector failed during refinement")
    y, J, s, it = c
    return _point(y, J, s, P["t"], it + 1)


def _refine(P, fun, xtol=1e-13):
    """Branch point between P and the next accepted point where fun(point) = 0 (brentq on sig)."""
    return _on_branch(P, brentq(lambda g: fun(_on_branch(P, g)), 0.0, P["ds"], xtol=xtol))


def _argmax_Q2(P):
    """Branch point of max |Q2| between P and the next accepted point (bounded Brent on sig)."""
    r = minimize_scalar(
        lambda g: -_on_branch(P, g)["Q2"],
        bounds=(0.0, P["ds"]),
        method="bounded",
        options=dict(xatol=1e-10),
    )
    return _on_branch(P, r.x)


def continuation(
    Omega_start=0.8,
    Omega_end=0.5,
    ds0=0.02,
    ds_min=1e-10,
    ds_max=0.08,
    cos_max_angle=0.995,
    ds_angle_free=1e-4,
    max_steps=5000,
    verbose=False,
):
    """Pseudo-arclength continuation of the period-1 orbit in y = (x0, W), Keller's
    constraint, exact Jacobian [Mon - I, dx(T)/dW]; adaptive ds (Newton count, tangent angle).
    At a grazing point (max q1 = 1, contact appears/disappears) the period map is C1 but not C2
    (its Jacobian varies like sqrt(distance)), so the tangent turns abruptly: the angle test is
    waived for ds <= ds_angle_free, and grazing points are reported (brentq on max q1 - 1).
    Returns dict of arrays along the branch (Omega, Q2, Q1 = fundamental amplitudes, max_q1,
    mu_max, stable, iters = Newton iterations per point, nswitch, x0) and lists of dicts
    folds (sign change of dW/ds), grazing (max q1 = 1), stability_changes (|mu|max = 1, with
    the critical multiplier and its kind), each refined on the branch by brentq on the
    arclength parameter; peak_Q2 / peak_Omega (bounded maximisation); counters, time_s."""
    t0 = time.perf_counter()
    po = periodic_orbit(Omega_start)
    assert po["converged"]
    y = np.append(po["x0"], Omega_start)
    R, J, s = _RJ(y)
    pts = [_point(y, J, s, -np.eye(5)[4], po["iterations"] + 1)]  # start towards decreasing W
    ds, nrej, done = ds0, 0, False
    for _ in range(max_steps):
        P = pts[-1]
        c = _correct(P["y"] + ds * P["t"], P["t"])
        if c is not None:
            Q = _point(*c[:3], P["t"], c[3] + 1)
            Q["iters"] = c[3]
        if c is None or (Q["t"] @ P["t"] < cos_max_angle and ds > ds_angle_free):
            ds *= 0.5
            nrej += 1
            if ds < ds_min:
                raise RuntimeError(f"step size underflow at W = {P['y'][4]}")
            continue
        Q["ds"] = P["ds"] = ds  # P['ds']: step from P to the next point
        if Q["y"][4] <= Omega_end:  # land exactly on W = Omega_end
            Q = _refine(P, lambda B: B["y"][4] - Omega_end, xtol=1e-14)
            Q["iters"], done = Q["nfev"] - 1, True
        pts.append(Q)
        if verbose:
            print(
                f"{len(pts):4d} W={Q['y'][4]:.6f} |Q2|={Q['Q2']:.5f} mu={Q['mu_max']:.4f} "
                f"it={c[3]} ds={ds:.2e}"
            )
        if done:
            break
        ds = float(
            np.clip(ds * (1.6 if c[3] <= 2 else (1.0 if c[3] <= 4 else 0.6)), ds_min, ds_max)
        )
    pts[0]["iters"] = po["iterations"]
    arr = lambda k: np.array([p[k] for p in pts])
    out = dict(
        Omega=arr("y")[:, 4],
        Q2=arr("Q2"),
        Q1=arr("Q1"),
        max_q1=arr("max_q1"),
        mu_max=arr("mu_max"),
        x0=arr("y")[:, :4],
        iters=arr("iters"),
        nswitch=arr("nswitch"),
        n_rejected=nrej,
        reached_end=done,
    )
    out["stable"] = out["mu_max"] < 1
    # --- turning points: sign change of dW/ds (t[4]); brentq on sig along the branch
    folds, stab, graz = [], [], []
    for k in range(len(pts) - 1):
        P, Q = pts[k], pts[k + 1]
        if (P["max_q1"] - GAP) * (Q["max_q1"] - GAP) < 0:
            Gp = _refine(P, lambda B: B["max_q1"] - GAP, xtol=1e-14)
            graz.append(
                dict(
                    Omega=Gp["y"][4],
                    Q2=Gp["Q2"],
                    Q1=Gp["Q1"],
                    mu_max=Gp["mu_max"],
                    index=k,
                    contact="starts" if P["max_q1"] < GAP else "ends",
                )
            )
        if P["t"][4] * Q["t"][4] < 0:
            F = _refine(P, lambda B: B["t"][4])
            folds.append(dict(Omega=F["y"][4], Q2=F["Q2"], Q1=F["Q1"], mu_max=F["mu_max"], index=k))
        if (P["mu_max"] - 1) * (Q["mu_max"] - 1) < 0:
            S = _refine(P, lambda B: B["mu_max"] - 1)
            mu = S["mu"][np.argmin(abs(abs(S["mu"]) - 1))]
            kind = (
                "fold (mu=+1)"
                if abs(mu - 1) < 1e-3
                else ("flip (mu=-1)" if abs(mu + 1) < 1e-3 else "Neimark-Sacker")
            )
            stab.append(
                dict(
                    Omega=S["y"][4],
                    Q2=S["Q2"],
                    mu=mu,
                    kind=kind,
                    index=k,
                    change="loses" if P["mu_max"] < 1 else "gains",
                )
            )
    # --- peak of |Q2|: bounded maximisation on sig in the two intervals around the discrete max
    k = int(np.argmax(out["Q2"]))
    best = (pts[k]["Q2"], pts[k])
    for j in (k - 1, k):
        if 0 <= j < len(pts) - 1:
            Pk = _argmax_Q2(pts[j])
            if Pk["Q2"] > best[0]:
                best = (Pk["Q2"], Pk)
    out.update(
        folds=folds,
        stability_changes=stab,
        grazing=graz,
        peak_Q2=best[0],
        peak_Omega=best[1]["y"][4],
        peak_max_q1=best[1]["max_q1"],
        n_points=len(pts),
        newton_total=int(out["iters"].sum()),
        time_s=time.perf_counter() - t0,
    )
    return out


# ---------------------------------------------------------------- validation
def validate(x_contact=None, Om_contact=None):
    """(a) Omega = 0.8 orbit vs linear FRF; (b) period_map vs DOP853 with events;
    (c) monodromy and dx(T)/dW vs central differences; (d) energy balance of a contact orbit;
    plus exact vs 4096-sample fundamental and eigen-form vs expm consistency."""
    res = {}
    po = periodic_orbit(0.8, x_guess=np.zeros(4))  # Newton from rest, not from the FRF itself
    Q, xl = linear_frf(0.8)
    h = harmonic_amplitudes(po["x0"], 0.8)
    res["a_x0_err"] = np.abs(po["x0"] - xl).max()
    res["a_amp_err"] = max(abs(h["Q1"] - abs(Q[0])), abs(h["Q2"] - abs(Q[1])))
    res["a_max_q1"] = h["max_q1"]
    res["a_nswitch"] = shoot(po["x0"], 0.8)["nswitch"]
    if x_contact is None:
        Om_contact = 0.7  # upper (stable, contact) branch; guess read off the continuation
        x_contact = periodic_orbit(Om_contact, x_guess=[-0.58, -0.56, 0.69, 0.34])["x0"]
    xs = [(x_contact, Om_contact), (np.array([1.3, 0.4, -0.7, 0.9]), 0.55)]
    res["contact_nswitch"] = [shoot(x, W)["nswitch"] for x, W in xs]
    res["b_ivp_rel_err"] = max(
        np.abs(period_map(x, W) - period_map_ivp(x, W)).max() / np.abs(period_map(x, W)).max()
        for x, W in xs
    )
    ec, eo = 0.0, 0.0
    for x, W in xs:
        s, hh = shoot(x, W), 1e-6
        fd = np.column_stack(
            [(period_map(x + hh * e, W) - period_map(x - hh * e, W)) / (2 * hh) for e in np.eye(4)]
        )
        ec = max(ec, np.abs(fd - s["mon"]).max() / np.abs(s["mon"]).max())
        fo = (period_map(x, W + hh) - period_map(x, W - hh)) / (2 * hh)
        eo = max(eo, np.abs(fo - s["dOm"]).max() / np.abs(s["dOm"]).max())
    res["c_monodromy_fd_rel_err"], res["c_dOmega_fd_rel_err"] = ec, eo
    Ein, Ed = energy_balance(x_contact, Om_contact)
    res["d_energy_rel_err"], res["d_E_in"] = abs(Ein - Ed) / abs(Ein), Ein
    t, X = sample_orbit(x_contact, Om_contact, 4096)
    hx = harmonic_amplitudes(x_contact, Om_contact)
    qs = 2 * np.abs((X[:, :2] * np.exp(-1j * Om_contact * t)[:, None]).mean(0))
    res["fourier_4096_vs_exact"] = max(abs(qs[0] - hx["Q1"]), abs(qs[1] - hx["Q2"]))
    res["sampled_max_q1_le_exact"] = bool(X[:, 0].max() <= hx["max_q1"] + 1e-14)
    z7 = np.r_[x_contact, 0.0, 1.0, 1.0]
    ee = 0.0
    for r in (OPEN, CLOSED):
        for tau in (0.3, 2.0):  # (mpmath: eigen form ~1e-14; expm ~1e-13 over long closed arcs)
            ee = max(
                ee,
                np.abs(
                    np.array(_xeval(r, 0.6, z7, tau, rows=range(4)))
                    - (expm(_aug13(r, 0.6)[np.ix_(I7, I7)] * tau) @ z7)[:4]
                ).max(),
            )
    res["eig_vs_expm"] = ee
    return res


if __name__ == "__main__":
    c = continuation()
    print(
        f"continuation: {c['n_points']} points, {c['newton_total']} Newton iterations, "
        f"{c['n_rejected']} rejected steps, {c['time_s']:.2f} s, reached W_end: {c['reached_end']}"
    )
    print(
        f"peak |Q2| = {c['peak_Q2']:.10f} at Omega = {c['peak_Omega']:.10f} "
        f"(max q1 = {c['peak_max_q1']:.6f})"
    )
    for f in c["folds"]:
        print(
            f"turning point: Omega = {f['Omega']:.10f}  |Q2| = {f['Q2']:.10f}  "
            f"|Q1| = {f['Q1']:.10f}  mu_max = {f['mu_max']:.8f}"
        )
    for g in c["grazing"]:
        print(
            f"grazing (contact {g['contact']}): Omega = {g['Omega']:.10f}  |Q2| = {g['Q2']:.10f}  "
            f"mu_max = {g['mu_max']:.8f}"
        )
    for s in c["stability_changes"]:
        print(
            f"stability {s['change']} ({s['kind']}): Omega = {s['Omega']:.10f}  "
            f"|Q2| = {s['Q2']:.10f}  mu = {s['mu']:.8f}"
        )
    kpk = int(np.argmin(abs(c["Omega"] - c["peak_Omega"]) + abs(c["Q2"] - c["peak_Q2"])))
    v = validate(c["x0"][kpk], c["Omega"][kpk])
    for k, val in v.items():
        print(f"  {k}: {val}")
    if "--plot" in sys.argv:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(7, 4.5))
        W, A2, st = c["Omega"], c["Q2"], c["stable"]
        for mask, ls, lab in ((st, "-", "stable"), (~st, "--", "unstable")):
            m = mask | np.r_[False, mask[:-1]]  # include the first point after each segment
            ax.plot(W, np.where(m, A2, np.nan), "k" + ls, label=f"|Q2| {lab}")
        ax.plot(W, c["Q1"], "b:", lw=1, label="|Q1|")
        ax.plot(
            [f["Omega"] for f in c["folds"]],
            [f["Q2"] for f in c["folds"]],
            "ro",
            label="turning points",
        )
        ax.plot(c["peak_Omega"], c["peak_Q2"], "g^", label="peak")
        ax.set(
            xlabel="Omega",
            ylabel="fundamental amplitude",
            title="NLvib ex. 03 (exact piecewise-linear reference)",
        )
        ax.legend()
        fig.savefig(sys.argv[sys.argv.index("--plot") + 1], dpi=120, bbox_inches="tight")
