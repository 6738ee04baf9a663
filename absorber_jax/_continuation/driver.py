"""Following a branch: the stateful driver (predictor, corrector, step control, the
Poincaré section moved where the absorbers fly free), the first orbit, batched
correctors over devices, bifurcation location and branch switching."""

from __future__ import annotations

import copy
import dataclasses
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.devices import (
    device_parts,
    lanes_on_devices,
    one_blas_thread,
    packed_lanes,
    replicated,
    split_over,
)
from .._core.status import Status, nan_where_failed
from .._core.units import signals_of
from .._integration.flow import (
    closed_form_flights,
    event_counts,
    integrate_flow,
    make_config,
    state_scale,
)
from .._periodic.orbit import finish_orbit, free_flight_apexes, has_rigid_walls, wall_kinematics
from .._systems.base import is_hybrid
from .branch import Bifurcation, Branch
from .constants import (
    APPROACH_MARGIN,
    CHORD_SAG,
    CLOSE_RETURN_PERIODS,
    CLOSE_RETURN_SKIP,
    CLOSE_RETURNS,
    CORNER_REDUCTION,
    CRAWL_MULTIPLIER,
    CRAWL_POINTS,
    CRAWL_REACH,
    GRAZING_LOOKBACK,
    GRAZING_SAMPLES,
    GRAZING_STEPS,
    GRAZING_TOL,
    JUMP_TOL,
    LOOP_TOL,
    RESECTION,
    RESECTION_SAME,
    RESECTION_TANGENT,
    RETRACE,
    RETRACE_SPIKE,
)
from .events import _events, _g
from .problem import (
    _corrector,
    _defect_vector,
    _jacobian,
    _Problem,
    _scale_in_section,
)
from .sequence import (
    event_log,
    sequence_of,
    sequence_with,
    sequence_without,
    solve_sequence,
)


class _Driver:
    """Holds the compiled corrector's inputs and the branch being built."""

    def __init__(self, prob, method, bounds):
        # the state scale and section held on the host: the driver reads them at every
        # point, and a batch stacks its lanes' (a device array would be copied back each
        # time)
        self.prob = dataclasses.replace(prob, s0=np.asarray(prob.s0),
                                        section=np.asarray(prob.section))
        self.method = method
        self.lo, self.hi = (b / float(prob.pscale) for b in bounds)

    def solve(self, z_pred, t_prev, patient=False):
        """The corrector from ``z_pred`` on the hyperplane normal to ``t_prev``, now
        (``patient``: the whole Newton budget, for a first orbit from a far guess)."""
        return self.point(*jax.device_get(_corrector(
            self.prob, jnp.asarray(z_pred), jnp.asarray(t_prev), self.method.tol,
            self.method.newton_steps, jnp.asarray(patient))))

    def point(self, z, t, ss, sec, sc):
        """A corrector's output (numpy arrays) as a branch point: ``xi`` its internal state
        on the driver's section, ``x0`` at ``t = 0``, ``sec`` its ``Section``, ``sc`` the
        state scale at its parameter value."""
        return dict(z=z, t=np.asarray(t), ss=ss, sec=sec, xi=z[:-1] * np.asarray(self.prob.s0),
                    x0=sec.at_zero, mult=np.asarray(ss.multipliers),
                    ok=int(ss.status) == Status.SUCCESS, sc=np.asarray(sc),
                    impacts=_counted(ss))

    def resection(self, point):
        """Move the branch's Poincaré section to where the orbit at ``point`` flies farthest
        from the contact walls, once the clearance at the current one has fallen below
        ``RESECTION`` of that (a generator of one corrector request, see ``_follow``):
        the point's state there, corrected at its parameter value, gives the unknowns and the
        tangent in the new section (oriented by the parameter's direction, so not near a
        fold: ``|t_p| >= RESECTION_TANGENT``).  Returns the point in the new unknowns, or
        ``point`` where nothing is to be moved or the correction failed."""
        sec, tp = point["sec"], float(point["t"][-1])
        # an impacting orbit: a sample in contact (a compliant wall), or impacts counted at
        # their events (rigid walls, whose samples never touch: an impact drifting through
        # the section makes the period map jump there)
        impacting = sec.least_clearance <= 0 or float(point["ss"].impacts) > 0
        if not (impacting and 0 < sec.best_clearance
                and sec.clearance < RESECTION * sec.best_clearance
                and abs(tp) >= RESECTION_TANGENT):
            return point
        old = self.prob
        self.prob = dataclasses.replace(
            old, section=np.asarray(int(sec.best), dtype=np.asarray(old.section).dtype))
        z = np.append(sec.best_state / np.asarray(self.prob.s0), point["z"][-1])
        e = np.zeros_like(z)
        e[-1] = np.sign(tp)
        c = yield (self, z, e, False)
        size = np.max(np.abs(point["x0"]))
        if c["ok"] and np.max(np.abs(c["x0"] - point["x0"])) < RESECTION_SAME * size:
            # the same orbit: its statistics and count as the point's
            c["ss"] = dataclasses.replace(c["ss"], iterations=point["ss"].iterations,
                                          residual=point["ss"].residual)
            return self.rescale(c)
        self.prob = old
        return point

    def rescale(self, point):
        """Rescale the state unknowns to the orbit at ``point`` (its state over the state
        scale there, at least 1): steps and tolerances then measure changes relative to
        the orbit's size, as it grows through a resonance.  The compiled corrector is
        reused (the scale is an array input).  Returns ``point`` in the new unknowns."""
        s_old = np.asarray(self.prob.s0)
        sc = point["sc"]
        s_new = sc * max(1.0, float(np.max(np.abs(point["xi"] / sc))))
        self.prob = dataclasses.replace(self.prob, s0=s_new)
        z, t = _in_scale(point, s_old, s_new)
        return dict(point, z=z, t=t, s0=s_new, section=int(self.prob.section))

    def locate(self, kind, a, h):
        """Illinois regula falsi on the arclength ``σ ∈ [0, h]`` from point ``a`` along its
        tangent for a zero of the test function of ``kind`` (a generator of corrector
        requests, see ``_follow``).  It stops where the next Illinois correction from the
        last point, or the bracket, is within ``locate_tol``: on a smooth test function the
        iterates converge superlinearly and the correction estimates the last point's error,
        so the bracket's far end, which regula falsi pulls in only by halving its value,
        need not be brought in too (the folds of the hard rigid band of
        scripts/benchmark_rigid_impacts.py: 3-13 solves each, most of them 5-7)."""
        lo, hi = 0.0, h
        glo, ghi = _g(kind, a), None
        b = yield (self, a["z"] + h * a["t"], a["t"], False)
        ghi = _g(kind, b)
        best, evals, side = b, 1, 0
        if not (np.isfinite(glo) and np.isfinite(ghi)) or glo * ghi > 0:
            return best, evals, False
        g_start = max(abs(glo), abs(ghi))
        converged = False

        def proposal():
            s = hi - ghi * (hi - lo) / (ghi - glo) if ghi != glo else 0.5 * (lo + hi)
            return s if min(lo, hi) < s < max(lo, hi) else 0.5 * (lo + hi)

        s = proposal()
        while evals < 60:
            p = yield (self, a["z"] + s * a["t"], a["t"], False)
            evals += 1
            if not p["ok"]:
                break
            gp = _g(kind, p)
            best = p
            if not np.isfinite(gp):
                break
            if gp * ghi < 0:
                lo, glo = hi, ghi
                hi, ghi = s, gp
                side = 0
            else:
                hi, ghi = s, gp
                if side == -1:
                    glo *= 0.5
                side = -1
            if gp == 0.0:
                converged = True
                break
            s = proposal()
            if abs(s - hi) <= self.method.locate_tol or abs(hi - lo) <= self.method.locate_tol:
                # a bracket shrunk onto a jump of the test function (a grazing corner,
                # where the multipliers leap across the circle) is not a located zero
                converged = min(abs(glo), abs(ghi)) <= JUMP_TOL * g_start
                break
        return best, evals, converged


def _config(system, forcing, parameter, lo, solver, rtol, atol, max_steps):
    # the integrator is chosen at the lowest frequency of the bounds in an omega continuation
    if parameter == "omega":
        forcing = forcing.with_omega(lo)
    return make_config(system, forcing, solver, rtol, atol, max_steps)


def _axis(prob, direction):
    """The parameter's unit direction in the unknowns (the first point's hyperplane)."""
    e = np.zeros(prob.s0.shape[0] + 1)
    e[-1] = 1.0 if direction == "up" else -1.0
    return e


def _bar(total, parameter, progress):
    """A tqdm bar over branch points (a context manager)."""
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=f"continuation in {parameter}", disable=not progress)


def _branch(points, bifs, termination, drv, value0, system, signals=None):
    """The ``Branch`` of the points followed (``signals``: the system's, when the caller
    builds many branches of one system)."""
    steady = jax.tree_util.tree_map(lambda *a: np.stack(a), *[q["ss"] for q in points])
    pscale = float(drv.prob.pscale)
    values = np.array([q["z"][-1] * pscale if "z" in q else value0 for q in points])
    return Branch(parameter=drv.prob.parameter, values=values, steady=nan_where_failed(steady),
                  bifurcations=tuple(bifs), period_multiple=drv.prob.n,
                  termination=termination, dof_names=tuple(system.output_names),
                  signals=signals_of(system) if signals is None else signals)


def _first_orbit(drv, guesses, e):
    """The first orbit that Newton reaches from one of ``guesses`` (tried in turn; at least
    one) on the hyperplane normal to ``e``, or the last failed one; a generator of corrector
    requests like ``_follow``."""
    for z0 in guesses:
        point = yield (drv, z0, e, True)
        if point["ok"]:
            break
    return point


def _close_returns(drivers, z0s, periods=CLOSE_RETURN_PERIODS, count=CLOSE_RETURNS,
                   lanes=None):
    """First guesses from a trajectory marched from each ``z0`` (one vmapped solve for all
    the drivers): the states after which it came closest to returning ``n`` periods later
    (distances scaled by the spread of the samples; the first ``CLOSE_RETURN_SKIP`` samples
    are transient and left out; one guess per near passage; none where the march failed).

    ``_periodic.marching.march`` keeps the single closest period-1 return of a
    march that never settles, for ``steady_state``'s retry (march from rest, then shoot:
    what ``continuation`` falls back on); this one keeps several, of period ``n``,
    for all the starts of a band in one program, without marching's settling tests and
    Floquet solve (``steady_state`` there would compile a program of its own per call).

    The marches run as ``lanes`` lanes (padded by repeating the first: every call of a band
    compiles one program), split over the local devices (the Hertz band's fill passes: 8
    marches 2.4 s on one CPU device)."""
    prob = drivers[0].prob
    k = len(drivers)
    size = max(k, lanes or k)
    parts = device_parts(size) if _split_lanes(prob) else 1
    at, slot, live = _placed(k, size, parts)
    s0 = np.stack([np.asarray(d.prob.s0) for d in drivers])
    z = np.stack(z0s)
    with one_blas_thread(parts):
        ys, st = jax.tree_util.tree_map(np.asarray, _march_many(
            prob, s0[slot], z[slot], live, periods, parts))
    out = []
    for y, s, z0 in zip(ys[at, CLOSE_RETURN_SKIP:], st[at], z0s):
        picks = []
        if s == Status.SUCCESS and np.all(np.isfinite(y)):
            d = np.max(np.abs(np.diff(y, axis=0)) / (np.std(y, axis=0) + 1e-12), axis=1)
            for j in np.argsort(d):
                if all(abs(j - k) > 1 for k in picks):
                    picks.append(j)
                if len(picks) == count:
                    break
        out.append([np.append(y[j], z0[-1]) for j in picks])
    return out


@eqx.filter_jit
def _march_many(prob, s0, z0, live, periods, ndev=1):
    """``_Problem.samples`` vmapped over state scales and starting points, the lanes
    split over ``ndev`` local devices (``lanes_on_devices``; ``live`` as
    ``_corrector_many``)."""
    def one(prob, s, z):
        return dataclasses.replace(prob, s0=s).samples(z, periods)

    return lanes_on_devices(one, prob, s0, z0, ndev=ndev, serial=is_hybrid(prob.system),
                            live=live)


def _follow(drv, first, rejoin, locate, bar, defer=False):
    """Follow the branch from the point ``first`` until it ends; a generator: it yields
    corrector requests ``(driver, z_pred, t_prev, patient)``, is sent the point solved for
    each and returns ``(points, bifurcations, termination)`` (``_run`` serves it one
    request at a time, ``_run_batched`` many branches' requests in one vmapped call).
    ``defer``: the bifurcations to locate are returned as the arguments of
    ``_bifurcation`` (a copy of the driver as it was), for the caller to locate them in
    batches with other branches' (``band_continuation``), instead of one after the other
    here, the branch's other steps waiting."""
    method = drv.method
    points = [(yield from drv.resection(drv.rescale(first))) if first["ok"] else first]
    bifs = []
    termination = "start_failed" if not first["ok"] else None
    h = method.step
    parameter, pscale = drv.prob.parameter, float(drv.prob.pscale)
    rigid = has_rigid_walls(drv.prob.system)
    checked = 0                 # points up to this one were looked at for a creep
    retried = False             # the step was cut since the last point
    bar.update(1)
    while termination is None:
        if len(points) >= method.max_points:
            termination = "max_points"
            break
        a = points[-1]
        b = yield (drv, _predict(points, h, method.max_angle), a["t"], False)
        turn = float(np.clip(b["t"] @ a["t"], -1.0, 1.0)) if b["ok"] else -1.0
        chord = b["z"] - a["z"]
        aside = float(np.clip(chord @ a["t"] / max(np.linalg.norm(chord), 1e-300), -1.0, 1.0))
        # a corner (the tangent turning abruptly where a contact starts to graze: the flow's
        # Jacobian varies like the square root of the distance to grazing) is accepted once
        # the step is below step / CORNER_REDUCTION and the corrector still converges; so is
        # a point off the tangent's line (the chord between the two points turned from it by
        # more than max_angle: on a smooth branch it turns half as much as the tangent; a
        # corrector drawn to a neighbouring branch lands aside)
        sharp = (b["ok"] and max(math.acos(turn), math.acos(aside)) > method.max_angle
                 and h > method.step / CORNER_REDUCTION)
        if not b["ok"] or sharp:
            if h <= method.min_step * (1 + 1e-12):
                bif, beyond = None, None
                if rigid:
                    bif, beyond = yield from _graze(drv, points, float(np.sign(a["t"][-1])))
                    if bif is not None:
                        bifs.append(bif)
                        if _passed_before(bifs):
                            termination = "closed"
                            break
                if beyond is None:
                    # a located grazing the branch could not pass, or a collapse elsewhere
                    located = bif is not None and bif.located
                    termination = "grazing" if located else "step_collapse"
                    break
                points.append(drv.rescale(beyond))
                bar.update(1)
                h = method.step
                continue
            h = max(_shrink(method, turn, aside, sharp) * h, method.min_step)
            retried = True
            continue
        if rigid and not _clear(drv, b) and _clear(drv, a) and _impacts(a) == _impacts(b):
            # a flight of b passes through a wall (an excursion shorter than an integrator
            # step, which event location does not see): not an orbit; the grazing between
            # a and b, then on from the orbit with the impact born there
            bif, beyond = yield from _through(drv, a, b, len(points) - 1)
            termination = _past_grazing(bifs, bif, beyond)
            if termination is not None:
                break
            points.append(drv.rescale(beyond))
            bar.update(1)
            h = method.step
            continue
        p_b = b["z"][-1]
        if not drv.lo <= p_b <= drv.hi:
            # land on the bound: a natural-parameter corrector from the interpolated point
            bound = drv.hi if p_b > drv.hi else drv.lo
            w = (bound - a["z"][-1]) / (p_b - a["z"][-1])
            zb = a["z"] + w * (b["z"] - a["z"])
            zb[-1] = bound
            e = np.zeros_like(zb)
            e[-1] = np.sign(p_b - a["z"][-1])
            c = yield (drv, zb, e, False)
            if c["ok"]:
                c["t"] = c["t"] * np.sign(c["t"] @ a["t"] or 1.0)
                b = c
            termination = "bounds"
        if termination is None and _retraced(points + [b], np.asarray(drv.prob.s0),
                                             method.max_angle):
            # back on a part of the branch followed already: its events were met there
            points.append(b)
            bar.update(1)
            termination = "closed"
            break
        for kind in _events(a, b):
            args = (copy.copy(drv), kind, a, b, len(points) - 1, locate,
                    float(np.linalg.norm(b["z"] - a["z"])))
            bifs.append(args if defer and locate else (yield from _bifurcation(*args)))
        if rigid and locate and _born(a, b):
            # an impact is born or dies between the two points: a grazing orbit
            bif = yield from _graze_between(drv, a, b, len(points) - 1, points[:-1])
            if bif.located or min(_impacts(a), _impacts(b)) == 0:
                bifs.append(bif)
                if _passed_before(bifs):
                    termination = "closed"
        points.append(b)
        bar.update(1)
        bar.set_postfix({parameter: f"{p_b * pscale:.6g}", "h": f"{h:.2g}"})
        if rejoin is not None and rejoin(b["x0"], b["z"][-1]):
            termination = "rejoined"
            break
        s_now = np.asarray(drv.prob.s0)
        back = np.append((b["x0"] - points[0]["x0"]) / s_now, b["z"][-1] - points[0]["z"][-1])
        if len(points) > 10 and np.linalg.norm(back) < 0.5 * h:
            termination = "closed"
            break
        points[-1] = drv.rescale(b)
        if termination is None and len(points) < method.max_points:
            points[-1] = yield from drv.resection(points[-1])
        if rigid and locate and termination is None and _crawling(points, checked):
            # creeping towards an impact's grazing: located on the sequence of events held
            # fixed, and the branch goes on beyond it (or ends there)
            checked = len(points) - 1
            e = np.zeros_like(b["z"])
            e[-1] = float(np.sign(b["z"][-1] - points[-2]["z"][-1])) or 1.0
            bif, beyond = yield from _graze_impacting(drv, points, e)
            if bif is not None:
                termination = _past_grazing(bifs, bif, beyond)
                if termination is not None:
                    break
                points.append(drv.rescale(beyond))
                bar.update(1)
                h = method.step
                continue
        h = min(max(_grow(method, int(b["ss"].iterations), turn, aside, retried) * h,
                    method.min_step), method.max_step)
        retried = False
    return points, bifs, termination


def _grow(method, iterations, turn, aside, retried):
    """The factor on the arclength step after an accepted one that took ``iterations``
    Newton steps and turned the tangent by ``acos(turn)``, the chord off it by
    ``acos(aside)``: 1.5 after an easy step (at most 3 iterations), 0.6 after a hard one
    (6 or more); no growth right after a rejected try (``retried``: the step that failed
    was at most twice this one); and no more than brings the expected turn (proportional
    to the step on a smooth branch) to half of ``max_angle``, so that the next step is not
    rejected as sharp."""
    grow = 1.5 if iterations <= 3 else (0.6 if iterations >= 6 else 1.0)
    if retried:
        grow = min(grow, 1.0)
    return min(grow, max(_half_turn(method, turn, aside), 0.5))


def _shrink(method, turn, aside, sharp):
    """The factor on the arclength step after a rejected try: a half where the corrector
    failed; where it converged to a point too far round (``sharp``: the tangent turned by
    ``acos(turn)`` or the chord by ``acos(aside)``, beyond ``max_angle``), what brings that
    turn to half of ``max_angle`` (between a tenth and a half)."""
    if not sharp:
        return 0.5
    return min(max(_half_turn(method, turn, aside), 0.1), 0.5)


def _half_turn(method, turn, aside):
    """The factor on a step that turned the tangent by ``acos(turn)`` and the chord off it
    by ``acos(aside)`` (half the tangent's turn on a smooth branch) that brings the turn,
    proportional to the step, to half of ``max_angle`` (inf where it did not turn)."""
    angle = max(math.acos(turn), 2 * math.acos(aside))
    return 0.5 * method.max_angle / angle if angle > 0 else math.inf

def _predict(points, h, max_angle):
    """The predictor a step ``h`` from the branch's last point ``a``: ``z_a + h t_a + h²κ/2``,
    ``κ`` the branch's curvature from the turn of the tangent since the point before (in
    ``a``'s unknowns: same section, its state scale), where the two lie on one smooth
    piece of the branch (the tangent turned by less than ``max_angle``; not across a
    grazing, where the branch has a corner), else the tangent's ``z_a + h t_a``.  The
    tangent predictor's error grows like ``h²``, this one's like ``h³``: on strongly
    unstable many-impact orbits, whose Newton basin is small, the step can be larger."""
    a = points[-1]
    z = a["z"] + h * a["t"]
    # balanced orbits' points (``balance._BalanceDriver``) carry no state scale of their
    # own: the tangent alone there
    if len(points) < 2 or "s0" not in a or points[-2]["section"] != a["section"]:
        return z
    zp, tp = _in_scale(points[-2], points[-2]["s0"], a["s0"])
    ds = float(np.linalg.norm(a["z"] - zp))
    if not ds > 0 or float(tp @ a["t"]) < math.cos(max_angle):
        return z
    bend = 0.5 * h * h * (a["t"] - tp) / ds
    return z + bend if np.linalg.norm(bend) <= 0.25 * h else z


def _in_scale(point, s_old, s_new):
    """Branch point ``point``'s unknowns and unit tangent, given in the state scale
    ``s_old``, in the state scale ``s_new``."""
    t = np.append(point["t"][:-1] * s_old / s_new, point["t"][-1])
    return np.append(point["xi"] / s_new, point["z"][-1]), t / np.linalg.norm(t)


def _retraced(points, s_now, max_angle):
    """Whether the branch's last point lies on a part of the branch followed already,
    going the same way (round a loop whose start is not the branch's first point: the
    snaking branches of impacting orbits pass a grazing again and go round once more).
    In the unknowns ``(x0 / s_now, p)`` (``x0`` the orbit's state at ``t = 0``, whatever
    the section), the last point projects inside an earlier chord (not one of the last
    two) whose ends have as many impacts a period as it, lies off it by no more than
    ``RETRACE`` of its length, and the last chord turns from it by less than
    ``max_angle``: a smooth branch passes near itself only where it retraces itself (points
    of one orbit), and its own curve sags from a chord turned by ``θ`` by about ``θ/8`` of
    it (a chord across a grazing corner joins two sheets, whose impacts differ).  A chord
    more than ``RETRACE_SPIKE`` times as long as both its neighbours is not one: the
    state at ``t = 0`` jumps where an impact crosses ``t = 0``, and such a chord is no
    piece of the branch's curve."""
    if len(points) < 5:
        return False
    X = np.column_stack([np.array([q["x0"] for q in points]) / s_now,
                         np.array([q["z"][-1] for q in points])])
    D = np.diff(X, axis=0)                                   # the chords
    chords = np.linalg.norm(D, axis=1)
    side = np.maximum(np.append(0.0, chords[:-1]), np.append(chords[1:], 0.0))
    smooth = chords <= RETRACE_SPIKE * side
    # the earlier chords (all but the last two) from their first points P
    P, d, length = X[:-3], D[:-2], chords[:-2]
    u = np.einsum("ij,ij->i", X[-1] - P, d) / np.where(length > 0, length**2, np.inf)
    off = np.linalg.norm(X[-1] - P - u[:, None] * d, axis=1)
    along = d @ D[-1] / np.maximum(length * chords[-1], 1e-300)
    # the same orbits: as many impacts as both ends of the chord (NaN where the orbits
    # count none: balanced ones)
    count = np.array([_impact_count(q) for q in points])

    def same_as_last(c):
        return (c == count[-1]) | (np.isnan(c) & np.isnan(count[-1]))

    same = same_as_last(count[:-3]) & same_as_last(count[1:-2])
    near = ((u >= 0) & (u <= 1) & (length > 0) & (off <= RETRACE * length)
            & (along >= math.cos(max_angle)) & same & smooth[:-2])
    return bool(np.any(near))


def _past_grazing(bifs, bif, beyond):
    """Record the grazing ``bif`` the branch has passed; its termination there (``"closed"``:
    a loop retraced, ``"grazing"``: no orbit ``beyond``), or None where it goes on."""
    bifs.append(bif)
    if _passed_before(bifs):
        return "closed"
    return "grazing" if beyond is None else None


def _passed_before(bifs):
    """Whether the branch has gone round a closed loop: its last two located grazings are
    two it passed already, one after the other (each the same orbit: its parameter value
    within ``LOOP_TOL`` relative, its state within ``LOOP_TOL`` of its size).  A grazing
    where sheets of impacting orbits meet may be passed again along another sheet; the same
    two in a row mean the branch retraces itself."""
    graz = [b for b in bifs if not isinstance(b, tuple) and b.kind == "grazing" and b.located]
    if len(graz) < 4 or graz[-1] is not bifs[-1]:
        return False

    def same(a, b):
        size = float(np.max(np.abs(b.state)))
        return (abs(a.value - b.value) <= LOOP_TOL * abs(b.value)
                and float(np.max(np.abs(a.state - b.state))) <= LOOP_TOL * size)

    return any(same(graz[k], graz[-2]) and same(graz[k + 1], graz[-1])
               for k in range(len(graz) - 3))


def _run(gen):
    """Serve one branch's corrector requests one at a time (the compiled corrector)."""
    try:
        request = next(gen)
        while True:
            request = gen.send(request[0].solve(*request[1:]))
    except StopIteration as stop:
        return stop.value


def _split_lanes(prob):
    """Whether a batch's lanes may be split over the local devices (``lanes_on_devices``):
    not for event-driven systems whose flights diffrax integrates (the implicit derivative
    of its event location fails to trace inside ``shard_map``); smooth systems and flights
    in closed form (``_integration.flights``) may."""
    system, forcing = prob.system, prob.forcing
    return not is_hybrid(system) or closed_form_flights(system, forcing, prob.cfg)


@eqx.filter_jit
def _corrector_many(prob, lanes, tol, newton_steps, ndev=1):
    """``_corrector`` vmapped over the branches' state scales, sections, predictors,
    hyperplanes and patience (the system, forcing and parameter scale shared), the lanes
    split over ``ndev`` local devices (``lanes_on_devices``; lanes whose ``live`` is False
    pad the batch, skipped where the lanes run one after the other).  ``lanes``: one row a
    lane, ``(s0, section, z_pred, t_prev, patient, live)`` side by side (``_lane_rows``:
    one transfer a call).  Returns the lanes' outputs packed into one array, and its
    layout (``packed_lanes``)."""
    s0, section, z_pred, t_prev, flags = jnp.split(
        lanes, np.cumsum(_lane_widths(prob.s0.shape[0]))[:-1], axis=1)
    section = section[:, 0].astype(jnp.asarray(prob.section).dtype)
    patient, live = flags[:, 0] > 0, flags[:, 1] > 0

    def one(prob, s, j, z, t, pa):
        return _corrector(dataclasses.replace(prob, s0=s, section=j), z, t, tol, newton_steps,
                          pa)

    return packed_lanes(lanes_on_devices(one, prob, s0, section, z_pred, t_prev, patient,
                                         ndev=ndev, serial=is_hybrid(prob.system), live=live))


def _lane_widths(n):
    """The columns of a row of ``_corrector_many``'s ``lanes`` for ``n`` states: the state
    scale, the section, the predictor and the hyperplane (``n + 1`` each, the parameter
    included), the patience and live flags (``_lane_rows`` writes them in that order)."""
    return (n, 1, n + 1, n + 1, 2)


def _lane_rows(reqs, live):
    """The corrector requests ``reqs`` (with the padding's ``live`` flags) as the rows of
    ``_corrector_many``'s ``lanes`` (``_lane_widths``)."""
    return np.concatenate([np.stack([r[0].prob.s0 for r in reqs]),
                           np.stack([r[0].prob.section for r in reqs])[:, None],
                           np.stack([r[1] for r in reqs]), np.stack([r[2] for r in reqs]),
                           np.asarray([bool(r[3]) for r in reqs])[:, None],
                           np.asarray(live)[:, None]], axis=1).astype(float)


def _placed(count, size, ndev):
    """Where a batch of ``size`` lanes (split into ``ndev`` equal parts, one per device)
    holds its ``count`` requests: dealt to the devices in turn, so that each gets its share
    where the lanes run one after the other.  Returns ``(at, slot, live)``: the lane of each
    request, the request each lane holds (the padding: the first again) and whether a lane
    is a real one."""
    part = size // ndev
    at = np.array([(j % ndev) * part + j // ndev for j in range(count)], dtype=int)
    slot = np.zeros(size, dtype=int)
    slot[at] = np.arange(count)
    live = np.zeros(size, dtype=bool)
    live[at] = True
    return at, slot, live


def _run_batched(gens, prob, method, lanes=None):
    """Serve many branches' corrector requests together: each round, one request from
    each of the first ``lanes`` branches still going (default one lane per branch), solved
    in one vmapped call of ``lanes`` lanes or, once no more than a quarter of that is
    pending, of that many (padded by repeating a request: the ends of branches do not
    recompile; callers that batch several phases give them all the same ``lanes``: one
    compilation per batch size, ~5 s each on the hard-contact scenes).  With several local
    devices a batch of at least two lanes per device is split into equal parts, one per
    device, in one SPMD program (``lanes_on_devices``): the Kelvin–Voigt band of
    scripts/benchmark_hard_contacts.py takes 47.8 s on two CPU devices against 59 s on one.
    One SPMD program traces the corrector's Jacobian integration once, where a program per
    device traces it per device (the first 16-lane call: 6.6 s against 10.8 s).

    Event-driven (hybrid) systems run their lanes one after the other (``lanes_on_devices``),
    the padding lanes skipped, in batches of ``lanes`` alone: the hard rigid band of
    scripts/benchmark_rigid_impacts.py ran 12016 lanes for 1840 requests, in 20 s where the
    padding, computed, had cost 45 s.  Their lanes are split over the local devices where
    their flights are in closed form (``_split_lanes``; on one device otherwise): that band
    19.0 s compiled on two CPU devices against 24.9 s on one (a machine 2.5 times slower
    than the other measurements here)."""
    lanes = len(gens) if lanes is None else lanes
    # the few branches snaking through folds, or locating bifurcations, go on for many more
    # rounds (the Kelvin–Voigt scene of scripts/benchmark_hard_contacts.py spent 39 of 55 s
    # on 60 rounds of 4 branches padded to 16 before the smaller batches): the batch is
    # cut to a quarter while no more than that is pending.  A half size in between cost
    # more compilation than it saved (the Kelvin-Voigt band on 2 CPU devices, one machine:
    # sizes 16/8/4 65.6 s, 16/4 60.9 and 62.1 s, 16/2 65.0 s, 16 alone 77.4 s, the same
    # 606 points; the Hertz band 123.9 s and 123.1 s)
    # lanes run one after the other (hybrid systems: see ``over_lanes``) skip the padding,
    # so one size serves: no second compilation
    serial = is_hybrid(prob.system)
    split = _split_lanes(prob)
    sizes = [lanes] + ([lanes // 4] if lanes >= 8 and not serial else [])
    results = [None] * len(gens)
    pending = {}
    shared = {}                 # prob placed on the devices, by their number
    for i, g in enumerate(gens):
        try:
            pending[i] = next(g)
        except StopIteration as stop:       # a branch that asks for nothing (start_failed)
            results[i] = stop.value
    while pending:
        idx = list(pending)[:sizes[0]]          # more requests than lanes: the first ones
        size = min(z for z in sizes if z >= len(idx))
        parts = device_parts(size) if split else 1
        at, slot, live = _placed(len(idx), size, parts)
        reqs = [pending[idx[k]] for k in slot]
        rows = split_over(_lane_rows(reqs, live), parts)
        if parts not in shared:
            shared[parts] = replicated(prob, parts)
        with one_blas_thread(parts):
            packed, layout = _corrector_many(shared[parts], rows, method.tol,
                                             method.newton_steps, parts)
            lanes = layout.lanes(np.asarray(jax.device_get(packed)), at)
        for lane, i in zip(lanes, idx):
            point = pending[i][0].point(*lane)
            try:
                pending[i] = gens[i].send(point)
            except StopIteration as stop:
                results[i] = stop.value
                del pending[i]
    return results


def _bifurcation(drv, kind, a, b, index, locate, h):
    if locate:
        p, evals, ok = yield from drv.locate(kind, a, h)
    else:
        p, evals, ok = (a if abs(_g(kind, a)) < abs(_g(kind, b)) else b), 0, False
    ss = p["ss"]
    return Bifurcation(kind=kind, value=float(p["z"][-1] * drv.prob.pscale),
                       amplitude=float(ss.amplitude), state=np.asarray(ss.state),
                       multipliers=np.asarray(ss.multipliers), index=index,
                       period_multiple=drv.prob.n, located=bool(ok), evaluations=evals)


def _bracket(args):
    """A deferred bifurcation's bracket (the arguments of ``_bifurcation``): its two ends
    as the public orbit state at ``t = 0`` followed by the parameter, comparable between
    half-branches whatever their sections and unknowns' scales."""
    drv, _, a, b = args[:4]
    pscale = float(drv.prob.pscale)
    return tuple(np.append(np.asarray(p["ss"].state, dtype=float), float(p["z"][-1]) * pscale)
                 for p in (a, b))


def _scaled(*ends):
    """Bracket ends (``_bracket``): the states over their largest magnitude, the parameter
    over its own."""
    ends = np.stack(ends)
    ref = np.full(ends.shape[1], max(float(np.max(np.abs(ends[:, :-1]))), 1e-300))
    ref[-1] = max(float(np.max(np.abs(ends[:, -1]))), 1e-300)
    return list(ends / ref)


def _overlap(u, v):
    """Whether two brackets (``_bracket``) overlap: their midpoints no farther apart than
    half their summed lengths."""
    a, b, c, d = _scaled(*u, *v)
    half = 0.5 * (np.linalg.norm(b - a) + np.linalg.norm(d - c))
    return np.linalg.norm(0.5 * (a + b - c - d)) <= half


def _inside(bracket, bif):
    """Whether the located bifurcation ``bif`` lies in ``bracket`` (``_bracket``): it
    projects onto the chord between the bracket's ends, between them, and lies no farther
    from the chord than ``CHORD_SAG`` of its length (a heuristic: a smooth branch turning by
    a small angle θ between two points sags from their chord by about θ/8 of it)."""
    if not bif.located:
        return False
    a, b, c = _scaled(*bracket, np.append(np.asarray(bif.state, dtype=float), bif.value))
    ab = b - a
    length2 = float(ab @ ab)
    if length2 == 0.0:
        return False
    u = float((c - a) @ ab) / length2
    off = np.linalg.norm(c - a - u * ab)
    return 0.0 <= u <= 1.0 and off <= CHORD_SAG * np.sqrt(length2)


def _shared(todo, owners):
    """For each deferred bifurcation in ``todo`` (the arguments of ``_bifurcation``; its
    half-branch ``owners[k]``), the position of an earlier one of the same kind whose
    bracket overlaps its own, else its own: the two half-branches of a band cell follow one
    branch from both ends and both see the bifurcations between them, and a half-branch
    that goes round a loop passes its bifurcations again.  Never two brackets next to each
    other on one half-branch (two bifurcations there are two); each is matched with at most
    one of each half-branch.  The first is located; the other takes that location where it
    lies in its own bracket (``_inside``), else is located in turn.  Returns the positions
    and the brackets."""
    brackets = [_bracket(args) for args in todo]
    first, claimed = [], set()
    for k, args in enumerate(todo):
        same = next((m for m in range(k) if first[m] == m and todo[m][1] == args[1]
                     and (owners[m] != owners[k] or abs(todo[m][4] - args[4]) > 1)
                     and (m, owners[k]) not in claimed
                     and _overlap(brackets[m], brackets[k])), k)
        if same != k:
            claimed.add((same, owners[k]))
        first.append(same)
    return first, brackets


def _switch(drv, system, forcing, bif, s0, p0, cfg, parameter, pscale):
    """The first point of the period-``2n`` branch born at the period doubling ``bif``, and
    the test that it has rejoined the period-``n`` branch."""
    n1 = bif.period_multiple
    prob1 = _Problem(system=system, forcing=forcing, s0=s0, pscale=jnp.asarray(pscale), cfg=cfg,
                     parameter=parameter, n=n1)
    x_star = np.asarray(system.to_internal(jnp.asarray(bif.state))) / np.asarray(s0)
    z_star = np.append(x_star, p0)
    J = np.asarray(_jacobian(prob1, jnp.asarray(z_star)))
    m = J.shape[0]
    mu, vecs = np.linalg.eig(J[:, :m] + np.eye(m))
    v = np.real(vecs[:, np.argmin(np.abs(mu + 1.0))])
    v = v / np.linalg.norm(v)
    tv = np.append(v, 0.0)
    first = None
    for delta in (0.02, 0.05, 0.1, 0.01, 0.005):
        cand = drv.solve(z_star + delta * tv, tv)
        # a genuine period-2n orbit, not the period-n one it branched from
        if cand["ok"] and _size(_defect_vector(prob1, jnp.asarray(cand["z"]))) > (
                1e3 * drv.method.tol):
            first = cand
            break
    if first is None:
        first = dict(ss=jax.tree_util.tree_map(np.asarray, cand["ss"]), ok=False, z=cand["z"],
                     t=cand["t"], mult=cand["mult"])
        first["ss"] = eqx.tree_at(lambda s: s.status, first["ss"],
                                  np.asarray(Status.NO_CONVERGENCE))
    d_first = _size(_defect_vector(prob1, jnp.asarray(first["z"]))) if first["ok"] else 0.0
    last = {}

    def rejoined(x0, p):
        """Whether the period-2n branch is back on the period-n one: its period-n defect
        ``d = Φ_nT(x) - x`` within 5 % of the first point's, or reversed since the point
        before while both stay below the first point's.  Near a flip ``d ≈ (μ - 1) a v =
        -2 a v``, ``a`` the distance along the flip's eigenvector, and the branch turns in
        the parameter where ``a`` passes zero (``Ω - Ω_flip ∝ a²``): points on either side
        of that turn may both stay above 5 % (NLvib 03's lower flip: 1e-6 rad/s away), and
        beyond it the branch retraces the same orbits shifted by n periods."""
        z = np.append(x0 / np.asarray(s0), p)
        d = np.asarray(_defect_vector(prob1, jnp.asarray(z)))
        size = _size(d)
        before, size_before = last.get("d"), last.get("size", np.inf)
        last.update(d=d, size=size)
        if not np.isfinite(size):
            return False
        if size < 0.05 * d_first:
            return True
        return (before is not None and size < d_first and size_before < d_first
                and float(d @ before) < 0)

    return first, rejoined


def _size(d):
    """``max |d|`` of a period map's defect (``_defect_vector``); inf where it failed."""
    d = np.asarray(d)
    return float(np.max(np.abs(d))) if np.all(np.isfinite(d)) else np.inf


@eqx.filter_jit
def _orbit_kinematics(system, forcing, x0, ts, cfg):
    """Each wall's penetration [m], its rate [m/s] and its acceleration [m/s²] along the
    orbit from internal state ``x0`` at ``ts[0] = 0``, saved at ``ts`` (``wall_kinematics``:
    the hybrid orbit, its impacts and holds included, sampled), and its impacts.  One
    compilation per system structure."""
    scale = state_scale(system, forcing)
    ys, _ = integrate_flow((system, forcing), x0 / scale, ts[-1], ts, cfg=cfg)
    impacts, _ = event_counts((system, forcing), x0 / scale, ts[-1], cfg)
    return wall_kinematics(system, forcing, ts, ys * scale), impacts


def _apexes(pen, rate, acc, dt, length, speed):
    """The apexes of free flight towards a wall (``free_flight_apexes``): their heights [m]
    and times [s] from the first sample."""
    turn, heights, times = free_flight_apexes(pen, rate, acc, dt, length, speed)
    return heights[turn], times[turn]


def _apex(pen, rate, acc, dt, length, speed):
    """The highest apex of free flight towards a wall (``_apexes``), ``-length`` when there
    is none."""
    heights, _ = _apexes(pen, rate, acc, dt, length, speed)
    return float(np.max(heights)) if heights.size else -length


def _approach(drv, point):
    """The orbit of branch point ``point``'s closest approach to a wall over its period
    [m] away from its impacts: the highest apex of its free flights between them
    (``_apex`` on ``GRAZING_SAMPLES`` samples per period of the hybrid orbit), negative
    while every flight stays clear, zero where one grazes a wall (a new impact is born) and
    positive where one passes through it (an excursion shorter than an integrator step,
    which event location does not see: then a positive value, as where the orbit
    integrated closely has more impacts).  Also the length scale of the motion [m].  Kept
    in ``point`` (a point is asked again while a grazing is bracketed).

    The corrector's own samples of the orbit (``Section.approach``, 256 a period at the
    branch's tolerance) decide where they put every flight farther than ``APPROACH_MARGIN``
    of the length scale from the walls: their apex heights are within ~1e-9 of the motion
    (cubic Hermite), and an excursion through a wall, seen or not by event location, shows
    on them as a flight reaching it.  Only orbits nearer grazing are integrated again
    closely (about 4 ms a point on the hard rigid scene of
    scripts/benchmark_rigid_impacts.py, 8 of its band's 30 s)."""
    if "approach" not in point:
        length = float(np.max(np.abs(np.asarray(drv.prob.s0))))
        coarse = float(point["sec"].approach)
        if coarse < -APPROACH_MARGIN * length:
            point["approach"] = (max(coarse, -length), length)
            return point["approach"]
        system, forcing = drv.prob.at(jnp.asarray(point["z"][-1]))
        # seen from phase 0: the forcing of the same type as a section's (_grazing_time),
        # so that _orbit_kinematics is traced and compiled once for both
        kinematics, dt, length, impacts = _sampled(drv, system, forcing.at_phase(0.0),
                                                   point["x0"])
        if impacts != _impacts(point):
            # the orbit integrated closely impacts where the branch's did not: one of its
            # flights passes through a wall
            g = GRAZING_TOL * length * 1e3
        else:
            g = _apex(*kinematics, dt, length, length * float(forcing.omega))
        point["approach"] = (g, length)
    return point["approach"]


def _sampled(drv, system, forcing, x0):
    """The walls' kinematics (``_orbit_kinematics``) of the orbit from internal state ``x0``
    at ``t = 0`` of ``forcing`` over the branch's response period, ``GRAZING_SAMPLES`` a
    period at rtol 1e-12: ``((penetrations, rates, accelerations), sample spacing [s],
    length scale of the motion [m], impacts)``."""
    n = int(drv.prob.n)
    ts = jnp.linspace(0.0, n * forcing.period, GRAZING_SAMPLES * n + 1)
    cfg = dataclasses.replace(drv.prob.cfg.over_periods(n), rtol=1e-12, atol=1e-12)
    kinematics, impacts = _orbit_kinematics(system, forcing, jnp.asarray(x0), ts, cfg)
    return (tuple(np.asarray(a) for a in kinematics), float(ts[1]),
            float(np.max(np.abs(np.asarray(drv.prob.s0)))), int(impacts))


def _counted(ss):
    """Impacts over the response period of the orbit whose ``SteadyState`` is ``ss``, as a
    whole number (a float), NaN where it counts none (a failed point, a balanced orbit)."""
    count = float(ss.impacts) * int(ss.period_multiple)
    return float(round(count)) if math.isfinite(count) else math.nan


def _impact_count(point):
    """``_counted`` of branch point ``point``'s orbit (kept in it by ``_Driver.point``)."""
    count = point.get("impacts")
    return _counted(point["ss"]) if count is None else count


def _impacts(point):
    """Impacts over the response period of branch point ``point`` (a solved one)."""
    return int(_impact_count(point))


def _born(a, b):
    """Whether an impact may be born (or die) between branch points ``a`` and ``b`` by a
    flight grazing a wall: their impacts differ, by one where both impact without holds
    (where the ball is held, the number of impacts of its chatter changes without
    grazing)."""
    ia, ib = _impacts(a), _impacts(b)
    if min(ia, ib) == 0:
        return ia != ib
    return abs(ia - ib) == 1 and float(a["ss"].contact_fraction) == 0 == float(
        b["ss"].contact_fraction)


def _locate_grazing(drv, clear, g_clear, hi, prev, e, chord, index):
    """The grazing orbit beyond branch point ``clear`` (free-flight closest approach
    ``g_clear < 0``, see ``_approach``) in the parameter direction ``e``: secant steps on
    the approach from the clear side (from ``prev``, an earlier clear ``(p, g)``, while no
    bracket is known), an iterate that impacts (or has no orbit) closing the bracket at
    ``hi`` from the other side (then halved).  Each iterate is a natural-parameter
    corrector solve predicted on the chord ``(za, zb)`` between two branch points, or from
    ``clear``'s orbit.  A generator of corrector requests; returns ``(Bifurcation, the
    orbit there)``."""
    tol = GRAZING_TOL * _approach(drv, clear)[1]
    lo, glo, best, evals, located = float(clear["z"][-1]), g_clear, clear, 0, False
    count = _impacts(clear)
    while evals < 60 and glo < -tol:
        p = None if hi is None else 0.5 * (lo + hi)
        if prev is not None and prev[1] != glo:
            sec = lo - glo * (lo - prev[0]) / (glo - prev[1])
            if hi is None or min(lo, hi) < sec < max(lo, hi):
                p = sec
        if p is None:
            break
        if chord is None:
            z = clear["z"].copy()
        else:
            za, zb = chord
            z = za + (p - za[-1]) / (zb[-1] - za[-1]) * (zb - za)
        z[-1] = p
        c = yield (drv, z, e, False)
        evals += 1
        g = _approach(drv, c)[0] if c["ok"] else 0.0
        if c["ok"] and _impacts(c) == count and g < -tol:
            prev, lo, glo, best = (lo, glo), p, g, c
        elif c["ok"] and _impacts(c) == count and g <= tol:
            best, glo, located = c, g, True     # touching within the tolerance
            break
        else:
            hi = p                      # another impact (or no orbit): beyond grazing
        if hi is not None and abs(hi - lo) <= GRAZING_TOL * max(1.0, abs(lo)):
            located = True
            break
    ss = best["ss"]
    return Bifurcation(kind="grazing", value=float(best["z"][-1] * drv.prob.pscale),
                       amplitude=float(ss.amplitude), state=np.asarray(ss.state),
                       multipliers=np.asarray(ss.multipliers), index=index,
                       period_multiple=drv.prob.n, located=bool(located),
                       evaluations=evals), best


def _graze(drv, points, direction):
    """At a step collapse of a branch with rigid impacts: if its last points near a wall
    (their closest approach rising towards zero, or past it), locate the grazing orbit
    (``_locate_grazing``), then solve the orbit a little beyond it.  A generator of
    corrector requests (as ``_follow``); returns ``(Bifurcation or None, the point
    beyond or None)``."""
    if len(points) < 2:
        return None, None
    # back to the last point clear of the walls: an excursion through a wall shorter than
    # one integrator step is not seen by the event location, so a branch may run a little
    # beyond grazing before its step collapses
    a = points[-1]
    tol = GRAZING_TOL * _approach(drv, a)[1]
    e = np.zeros_like(a["z"])
    e[-1] = direction
    later, i = None, len(points) - 1
    c_i = _approach(drv, points[i])[0]
    while i > 0 and len(points) - i <= GRAZING_LOOKBACK and c_i >= -tol:
        later, i = points[i], i - 1
        c_i = _approach(drv, points[i])[0]
    # the clear point's flights approach a wall; those after it (through the wall, or with
    # the impact born there) have at least its impacts
    if c_i >= -tol or any(_impacts(q) < _impacts(points[i]) for q in points[i + 1:]):
        return None, None
    prev = None
    if later is None:
        # still clear: the grazing lies ahead, extrapolated from the previous point
        cp = _approach(drv, points[i - 1])[0]
        if not cp < c_i:
            return None, None
        prev = (float(points[i - 1]["z"][-1]), cp)
    bif, best = yield from _locate_grazing(
        drv, points[i], c_i, None if later is None else float(later["z"][-1]), prev, e,
        None if later is None else (points[i]["z"], later["z"]), len(points) - 1)
    return (yield from _beyond(drv, bif, best, direction, e))


def _through(drv, a, b, index):
    """Branch point ``b`` has a flight through a wall that ``a``'s flights clear (with as
    many impacts): locate the grazing orbit between them (``_locate_grazing`` from ``a``,
    on their chord) and solve the orbit beyond it (``_beyond``).  A generator of corrector
    requests; returns ``(Bifurcation, the point beyond or None)``."""
    e = np.zeros_like(a["z"])
    e[-1] = np.sign(float(b["z"][-1]) - float(a["z"][-1])) or 1.0
    bif, best = yield from _locate_grazing(drv, a, _approach(drv, a)[0], float(b["z"][-1]),
                                           None, e, (a["z"], b["z"]), index)
    return (yield from _beyond(drv, bif, best, float(e[-1]), e))


def _beyond(drv, bif, best, direction, e):
    """The orbit with the impact born at the grazing orbit ``best`` (of ``bif``), reached
    from it with the whole Newton budget (the period map's derivative grows like the
    inverse square root of the distance to grazing), a larger step where a small one fails;
    ahead first, then behind (where the new branch folds back at grazing: a nonsmooth
    fold).  A generator of corrector requests; returns ``(bif, the point or None)``, its
    tangent leading away from the grazing orbit."""
    count = _impacts(best)
    c = yield from _onto_born(drv, best, direction, e)
    if c is not None:
        return bif, c
    for side in (1.0, -1.0):
        for frac in GRAZING_STEPS:
            z = best["z"].copy()
            z[-1] = best["z"][-1] + side * direction * frac * drv.method.step
            c = yield (drv, z, e, True)
            if c["ok"] and _impacts(c) != count and _clear(drv, c):
                c["t"] = c["t"] * np.sign(c["t"] @ (c["z"] - best["z"]) or 1.0)
                return bif, c
    return bif, None


def _crawling(points, checked):
    """Whether the branch creeps towards a grazing impact (an impact whose speed falls to
    zero): over its last ``CRAWL_POINTS`` points (none of them looked at already: after
    index ``checked``), all solved, as many impacts each and no hold, the largest
    ``|multiplier|`` growing at every point to beyond ``CRAWL_MULTIPLIER`` (the saltation of
    an impact at speed ``w`` grows like ``1/w``) while the parameter moves one way by
    shrinking steps (Newton's basin shrinks with ``w``: each step takes a fraction of what
    remains, and the branch would never reach it)."""
    last = points[-(CRAWL_POINTS + 1):]
    if len(last) <= CRAWL_POINTS or len(points) - 1 - checked < CRAWL_POINTS:
        return False
    if not all(q["ok"] and _impacts(q) == _impacts(last[0]) and _impacts(q) > 0
               and float(q["ss"].contact_fraction) == 0 for q in last):
        return False
    mu = np.array([float(np.max(np.abs(q["mult"]))) for q in last])
    dp = np.diff([float(q["z"][-1]) for q in last])
    return bool(np.all(np.diff(mu) > 0) and mu[-1] >= CRAWL_MULTIPLIER
                and (np.all(dp > 0) or np.all(dp < 0)) and abs(dp[-1]) < abs(dp[0]))


def _events_of(drv, point):
    """The event log of branch point ``point``'s orbit over its response period from its
    state on the section (``sequence.event_log``): ``(times, modes, period [s])``, or None
    where that integration failed."""
    system, forcing = drv.prob.in_section(jnp.asarray(point["z"][-1]))
    n = int(drv.prob.n)
    period = n * float(forcing.period)
    sc = point["sc"]
    times, modes, status = event_log(system, forcing, jnp.asarray(point["xi"] / sc),
                                     jnp.asarray(period), drv.prob.cfg.over_periods(n))
    return None if int(status) != Status.SUCCESS else (times, modes, period)


def _sequence_at(drv, seq, xi, p):
    """The orbit of the event sequence ``seq`` held fixed at scaled parameter ``p``, from
    internal state ``xi`` on the section (and ``seq``'s event times): ``(internal state,
    event times over the period, switch rates at the events)`` or None where Newton failed
    (``sequence.solve_sequence``)."""
    theta, seg, active = seq
    system, forcing = drv.prob.in_section(jnp.asarray(p))
    sc = np.asarray(_scale_in_section(drv.prob, jnp.asarray(p)))
    n = int(drv.prob.n)
    u, status, _, rates = solve_sequence(system, forcing, n,
                                         jnp.asarray(np.concatenate([xi / sc, theta])),
                                         jnp.asarray(seg), jnp.asarray(active),
                                         drv.prob.cfg.over_periods(n))
    if int(status) != Status.SUCCESS:
        return None
    u = np.asarray(u)
    N = sc.shape[0]
    return u[:N] * sc, u[N:], np.asarray(rates)


@eqx.filter_jit
def _orbit_of(prob, xi, p):
    """The ``SteadyState`` of the orbit through internal state ``xi`` on ``prob``'s section
    at scaled parameter ``p``, taken as periodic (a fixed-sequence solution), its
    multipliers from the flow's Jacobian."""
    system, forcing = prob.in_section(p)
    sc = state_scale(system, forcing)
    ss, _ = finish_orbit(system, forcing, xi / sc, prob.n, prob.cfg,
                         jnp.asarray(Status.SUCCESS), jnp.zeros(()), jnp.zeros((), int),
                         n_cap=prob.n, section=prob.section)
    return ss


def _graze_impacting(drv, points, e):
    """The grazing orbit the branch creeps towards from the impacting side (``_crawling``),
    and the orbit beyond it.  The sequence of events of the last point's orbit held fixed
    is smooth through the grazing (``sequence``): the speed of its slowest free-flight
    impact, solved there and at the point before, is extrapolated to zero by secant steps
    on the parameter, each a fixed-sequence solve; at the zero the impact grazes.  Beyond
    it the orbit has that impact no more (its flight turns short of the wall): the sequence
    without it, solved a fraction ``GRAZING_STEPS`` of the step ahead (then behind: a
    nonsmooth fold), is corrected by shooting and kept where it has one impact fewer and
    no flight through a wall.  A generator of corrector requests; returns
    ``(Bifurcation or None, the point beyond or None)``."""
    a, b = points[-2], points[-1]
    pa, pb = float(a["z"][-1]), float(b["z"][-1])
    logged = _events_of(drv, b)
    seq = None if logged is None else sequence_of(*logged)
    if seq is None:
        return None, None
    _, seg, active = seq
    at_b = _sequence_at(drv, seq, b["xi"], pb)
    at_a = None if at_b is None else _sequence_at(drv, (at_b[1], seg, active), at_b[0], pa)
    if at_a is None:
        return None, None
    K = int(np.sum(active))
    free = [j for j in range(K) if np.array_equal(seg[j], seg[j + 1])]
    if not free:
        return None, None
    j = min(free, key=lambda k: at_b[2][k])
    fa, fb = at_a[2][j], at_b[2][j]
    if not 0 < fb < fa:
        return None, None
    x, th, located = at_b[0], at_b[1], False
    p_prev, f_prev, p, f = pa, fa, pb, fb
    reach = CRAWL_REACH * abs(pb - pa)
    for _ in range(12):
        p_new = p - f * (p - p_prev) / (f - f_prev)
        if not abs(p_new - pb) <= reach:
            return None, None
        got = _sequence_at(drv, (th, seg, active), x, p_new)
        if got is None:
            return None, None
        p_prev, f_prev, p = p, f, p_new
        x, th, rates = got
        f = rates[j]
        if abs(p - p_prev) <= GRAZING_TOL * max(1.0, abs(p)):
            located = True
            break
    if not located:
        return None, None
    # the grazing orbit, shot at its parameter value from the sequence's state; where
    # shooting fails there (the impact at zero speed: the period map is not smooth at
    # its own solution), the fixed-sequence orbit itself, its multipliers those of the
    # impacting side
    z = np.append(x / np.asarray(drv.prob.s0), p)
    best = yield (drv, z, e, True)
    ss = (best["ss"] if best["ok"]
          else jax.tree_util.tree_map(np.asarray, _orbit_of(drv.prob, jnp.asarray(x),
                                                            jnp.asarray(p))))
    bif = Bifurcation(kind="grazing", value=float(p * drv.prob.pscale),
                      amplitude=float(ss.amplitude), state=np.asarray(ss.state),
                      multipliers=np.asarray(ss.multipliers), index=len(points) - 1,
                      period_multiple=drv.prob.n, located=True, evaluations=1)
    without = sequence_without(th, seg, active, j)
    if without is None:
        return bif, None
    count = _impacts(b)
    ahead = float(np.sign(p - pb)) or 1.0
    for side in (1.0, -1.0):
        for frac in GRAZING_STEPS:
            q = p + side * ahead * frac * drv.method.step
            got = _sequence_at(drv, without, x, q)
            if got is None or not np.all(got[2][:K - 1] > 0):
                continue
            c = yield (drv, np.append(got[0] / np.asarray(drv.prob.s0), q), e, True)
            if c["ok"] and _impacts(c) == count - 1 and _clear(drv, c):
                c["t"] = c["t"] * np.sign(c["t"] @ (c["z"] - z) or 1.0)
                return bif, c
    return bif, None


def _grazing_time(drv, point):
    """The time [s] after the section of the highest apex of the free flights of branch
    point ``point``'s orbit (a grazing orbit: where the new impact is born), or None."""
    system, forcing = drv.prob.in_section(jnp.asarray(point["z"][-1]))
    kinematics, dt, length, _ = _sampled(drv, system, forcing, point["xi"])
    heights, times = _apexes(*kinematics, dt, length, length * float(forcing.omega))
    return float(times[np.argmax(heights)]) if heights.size else None


def _onto_born(drv, best, direction, e):
    """The orbit with the impact born at the grazing orbit ``best``, from the sequence of
    its events with a zero-speed impact added at its grazing apex, solved with that
    sequence held fixed (``sequence.solve_sequence``: smooth through grazing, where the
    period map is not) a fraction ``GRAZING_STEPS`` of the step ahead, then behind; then
    corrected by shooting from that orbit's state on the section, and kept where it has the
    new impact and no flight through a wall.  A generator of corrector requests; returns
    the point (its tangent leading away from the grazing orbit) or None."""
    p_g = float(best["z"][-1])
    logged = _events_of(drv, best)
    t_new = _grazing_time(drv, best)
    if logged is None or t_new is None:
        return None
    seq = sequence_with(*logged[:2], t_new, logged[2])
    if seq is None:
        return None
    count = _impacts(best)
    for side in (1.0, -1.0):
        for frac in GRAZING_STEPS:
            p = p_g + side * direction * frac * drv.method.step
            got = _sequence_at(drv, seq, best["xi"], p)
            if got is None or not np.all(got[2][seq[2]] > 0):
                continue            # the new impact would be reached from beyond its wall
            c = yield (drv, np.append(got[0] / np.asarray(drv.prob.s0), p), e, True)
            if c["ok"] and _impacts(c) == count + 1 and _clear(drv, c):
                c["t"] = c["t"] * np.sign(c["t"] @ (c["z"] - best["z"]) or 1.0)
                return c
    return None


def _clear(drv, point):
    """Whether no flight of branch point ``point`` passes through a wall."""
    g, length = _approach(drv, point)
    return g <= GRAZING_TOL * length


def _graze_between(drv, a, b, index, earlier=()):
    """The grazing orbit between branch points ``a`` and ``b``, where impacts appear or
    vanish (``_locate_grazing`` from the clear one, predicted on the chord between them).
    A generator of corrector requests; returns the ``Bifurcation``."""
    clear, touch = (a, b) if _impacts(a) < _impacts(b) else (b, a)
    g_clear, scale = _approach(drv, clear)
    tol = GRAZING_TOL * scale
    # a clear point may lie a little beyond grazing already (an excursion through the wall
    # shorter than an integrator step): back to the last one whose approach is negative
    back = list(earlier)[::-1][:GRAZING_LOOKBACK] if clear is a else []
    for q in back:
        if g_clear < -tol or _impacts(q) != _impacts(clear):
            break
        clear, a, g_clear = q, q, _approach(drv, q)[0]
    e = np.zeros_like(a["z"])
    e[-1] = np.sign(float(b["z"][-1]) - float(a["z"][-1])) or 1.0
    bif, _ = yield from _locate_grazing(drv, clear, g_clear, float(touch["z"][-1]), None, e,
                                        (a["z"], b["z"]), index)
    return bif
