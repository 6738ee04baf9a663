"""matplotlib figures of frequency responses, continuation branches and bifurcation
diagrams.

Labels come from the results' own names and units (``result.signals``,
``absorber_jax._core.units``): the observable's name (``x1``, ``floor3``, ``floor3 -
floor2``), SI values shown in milli-units where that reads better (metres as mm, radians
as mrad), the unit in the label.  Failed points (``status != 0``) have no value: the lines
break there and a red cross on the bottom edge of the axes marks each.  Every legend entry
is the artist drawn, so its marker is the plotted one.
"""

from __future__ import annotations

import numpy as np

from .._core.units import axis_label, display_scale, unit_of, with_unit

# how a failed point is drawn: a red cross on the bottom edge of the axes (x in data
# coordinates, y in axes coordinates), outside the clipping box
FAILED_STYLE = dict(marker="x", ls="none", color="red", ms=6, mew=1.5, clip_on=False,
                    zorder=5)
# the line of a frequency response (NaN at failed points: it breaks there)
RESPONSE_GID = "response"


def _axes(path, ax):
    """(pyplot, ax, own): a new figure when ``ax`` is None (Agg when writing ``path``)."""
    import matplotlib

    if path is not None:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if ax is None:
        return plt, plt.subplots(figsize=(8, 4.5))[1], True
    return plt, ax, False


def _save(plt, ax, own, path):
    if own and path is not None:
        ax.figure.tight_layout()
        ax.figure.savefig(path, dpi=110)
        plt.close(ax.figure)
    return ax


def _scale_and_unit(si_unit, scale, unit):
    """``(factor, unit shown)``: ``unit`` when given (with ``scale`` or 1), else the
    displayed unit of ``display_scale`` (``scale`` None), else ``scale`` applied to
    the SI unit."""
    if unit is not None:
        return (1.0 if scale is None else float(scale)), unit
    if scale is None:
        return display_scale(si_unit)
    factor, shown = display_scale(si_unit)
    if float(scale) == 1.0:
        return 1.0, si_unit
    if float(scale) == factor:
        return factor, shown
    return float(scale), f"{si_unit} x {float(scale):g}"


def mark_failed(ax, x, label=None):
    """Red crosses at ``x`` on the bottom edge of ``ax`` (failed points, which have no
    value); returns the artist (None when ``x`` is empty)."""
    x = np.asarray(x, dtype=float)
    if x.size == 0:
        return None
    return ax.plot(x, np.zeros_like(x), transform=ax.get_xaxis_transform(), label=label,
                   **FAILED_STYLE)[0]


def _label_once(seen, key, text):
    """``text`` the first time ``key`` is seen, else None (one legend entry per style)."""
    if key in seen:
        return None
    seen.add(key)
    return text


def _sweep_words(direction):
    return {"up": "ω increasing", "down": "ω decreasing"}.get(direction, "")


def plot_frequency_response(frfs, path=None, *, title="", ax=None, label_prefix="",
                            field="amplitude", dof=None, scale=None, unit=None):
    """``field`` (amplitude, rms or harmonic) of the observable, or of the degree of
    freedom ``dof`` (``dof_<field>``), against ω for one or several
    [`FrequencyResponse`][absorber_jax.FrequencyResponse].

    A thin grey line joins the solved points (broken at failed ones); filled markers:
    stable orbits, open markers: unstable, colour by period multiple (period-1, and
    subharmonics n > 1); red crosses on the bottom edge: failed points.  Sweeps followed
    point by point are told apart by their marker (▲ ω increasing, ▼ ω decreasing).
    ``scale``, ``unit``: the values' display factor and unit (default metres as mm).
    The y label names the observable (or ``dof``) and the unit."""
    plt, ax, own = _axes(path, ax)
    if not isinstance(frfs, (list, tuple)):
        frfs = [frfs]
    colors = plt.get_cmap("tab10")
    markers = {"up": "^", "down": "v"}
    key = field if dof is None else "dof_" + field
    sig = frfs[0].signals
    factor, shown = _scale_and_unit(unit_of(key, sig, dof), scale, unit)
    seen = set()
    for frf in frfs:
        om = np.asarray(frf.omegas, dtype=float)
        values = (np.asarray(getattr(frf, field), dtype=float) if dof is None
                  else np.asarray(frf.dof(dof, field), dtype=float))
        values = np.atleast_2d(values)
        status = np.atleast_2d(np.asarray(frf.status))
        stable = np.atleast_2d(np.asarray(frf.stable)).astype(bool)
        multiple = np.atleast_2d(np.asarray(frf.period_multiple))
        mk = markers.get(frf.direction, "o")
        for p in range(values.shape[0]):
            ok = status[p] == 0
            y = np.where(ok, values[p], np.nan) * factor
            parts = [label_prefix.strip(), _sweep_words(frf.direction)]
            if frf.params:
                parts.append(", ".join(f"{k}={np.asarray(v)[p]:.3g}"
                                       for k, v in frf.params.items()))
            tag = ", ".join(s for s in parts if s)
            tag = tag + ": " if tag else ""
            ax.plot(om, y, "-", lw=0.6, color="0.6", gid=RESPONSE_GID)
            for n in np.unique(multiple[p][ok]):
                sel = ok & (multiple[p] == n)
                c = colors((int(n) - 1) % 10)
                if (sel & stable[p]).any():
                    ax.plot(om[sel & stable[p]], y[sel & stable[p]], mk, ls="none", ms=4,
                            color=c, label=_label_once(seen, (tag, mk, n, True),
                                                       f"{tag}period-{n} stable"))
                if (sel & ~stable[p]).any():
                    ax.plot(om[sel & ~stable[p]], y[sel & ~stable[p]], mk, ls="none", ms=5,
                            mfc="none", color=c,
                            label=_label_once(seen, (tag, mk, n, False),
                                              f"{tag}period-{n} unstable"))
            if (~ok).any():
                mark_failed(ax, om[~ok], label=_label_once(
                    seen, (tag, "failed"), f"{tag}failed ({int((~ok).sum())} points)"))
    ax.set(xlabel=with_unit("forcing frequency ω", "rad/s"),
           ylabel=axis_label(key, sig, dof, unit=shown), title=title)
    ax.grid(alpha=0.3)
    if seen:
        ax.legend(fontsize=7)
    return _save(plt, ax, own, path)


BIFURCATION_STYLE = {"fold": ("o", "black", "fold"),
                     "period_doubling": ("s", "tab:red", "period doubling"),
                     "neimark_sacker": ("D", "tab:green", "Neimark–Sacker"),
                     "grazing": ("^", "tab:purple", "grazing")}


def _parameter_label(br):
    p = br.parameter
    if p == "omega":
        return with_unit("forcing frequency ω", "rad/s")
    if p == "amplitude":
        return with_unit("forcing amplitude F0", "N")
    return with_unit(p, br.signals.parameter_unit(p))


def plot_branches(branches, path=None, *, ax=None, dof=None, field="amplitude", title="",
                  scale=None, unit=None):
    """Frequency–response curves from [`continuation`][absorber_jax.continuation]: stable parts
    solid, unstable parts dashed, one colour per period multiple, bifurcations marked (fold ●,
    period doubling ■, Neimark–Sacker ◆; filled where located onto a zero of the test function,
    open where the bracket closed on a jump of it), failed points as red crosses on the
    bottom edge (the curve breaks there).  ``dof``: plot ``dof_<field>`` at that degree of
    freedom (default the system's observable, ``field`` = amplitude, rms or harmonic);
    ``scale``, ``unit``: the values' display factor and unit (default metres as mm)."""
    plt, ax, own = _axes(path, ax)
    if not isinstance(branches, (list, tuple)):
        branches = [branches]
    colors = plt.get_cmap("tab10")
    key = field if dof is None else "dof_" + field
    sig = branches[0].signals
    factor, shown = _scale_and_unit(unit_of(key, sig, dof), scale, unit)
    seen = set()
    for br in branches:
        x = np.asarray(br.values, dtype=float)
        ok = np.asarray(br.status) == 0
        y = (np.asarray(getattr(br, field), dtype=float) if dof is None
             else np.asarray(br.dof(dof, field), dtype=float))
        y = np.where(ok, y, np.nan) * factor
        st = np.asarray(br.stable).astype(bool)
        c = colors((br.period_multiple - 1) % 10)
        # segment (i, i+1) solid when both ends are stable, dashed otherwise; runs of one
        # style drawn as one line; a failed end leaves the segment out
        seg = [(bool(ok[i] and ok[i + 1]), bool(st[i] and st[i + 1]))
               for i in range(len(x) - 1)]
        i = 0
        while i < len(seg):
            j = i
            while j + 1 < len(seg) and seg[j + 1] == seg[i]:
                j += 1
            valid, stable = seg[i]
            if valid:
                words = "stable" if stable else "unstable"
                ax.plot(x[i:j + 2], y[i:j + 2], "-" if stable else "--", color=c,
                        lw=1.4 if stable else 1.0,
                        label=_label_once(seen, (br.period_multiple, stable),
                                          f"period-{br.period_multiple} {words}"))
            i = j + 1
        for b in br.bifurcations:
            mk, col, name = BIFURCATION_STYLE[b.kind]
            if dof is None and field == "amplitude":
                yb = float(b.amplitude) * factor
            else:
                xs, ys = x[b.index:b.index + 2], y[b.index:b.index + 2]
                order = np.argsort(xs)
                yb = float(np.interp(b.value, xs[order], ys[order]))
            text = name if b.located else f"{name} (not located: a jump)"
            ax.plot([b.value], [yb], mk, ls="none", color=col, ms=6,
                    mfc=col if b.located else "white",
                    label=_label_once(seen, (b.kind, bool(b.located)), text))
        if (~ok).any():
            mark_failed(ax, x[~ok], label=_label_once(seen, "failed", "failed"))
    ax.set(xlabel=_parameter_label(branches[0]), ylabel=axis_label(key, sig, dof, unit=shown),
           title=title)
    ax.grid(alpha=0.3)
    if seen:
        ax.legend(fontsize=7)
    return _save(plt, ax, own, path)


def plot_bifurcation_diagram(maps, path=None, *, ax=None, title="", scale=None, unit=None):
    """Stroboscopic bifurcation diagram from
    [`bifurcation_diagram`][absorber_jax.bifurcation_diagram]: the observable at ``t = kT`` over the
    statistics window, for every initial state, against ``ω``; periodic responses in colour by
    period multiple (a period-n orbit shows n points; the period of the attractor the state
    reaches, ``AttractorMap.periods``), the others grey.  ``scale``, ``unit``: the
    values' display factor and unit (default metres as mm)."""
    plt, ax, own = _axes(path, ax)
    colors = plt.get_cmap("tab10")
    sig = maps[0].signals
    factor, shown = _scale_and_unit(unit_of("section", sig), scale, unit)
    seen = set()
    for m in maps:
        periods = m.periods()
        for k in range(m.section.shape[0]):
            n = int(periods[k])
            ok = n > 0
            c = colors((n - 1) % 10) if ok else "0.6"
            lab = (f"period-{n}" if ok else "not periodic")
            ax.plot(np.full(m.section.shape[1], m.omega), m.section[k] * factor, ".",
                    ls="none", ms=1.5, color=c, label=_label_once(seen, lab, lab))
    ax.set(xlabel=with_unit("forcing frequency ω", "rad/s"),
           ylabel=axis_label("section", sig, unit=shown), title=title)
    ax.grid(alpha=0.3)
    if seen:
        ax.legend(fontsize=7, markerscale=4)
    return _save(plt, ax, own, path)
