"""matplotlib figures of frequency responses."""

from __future__ import annotations

import numpy as np


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


def plot_frequency_response(frfs, path=None, *, title="", ax=None, label_prefix=""):
    """Primary amplitude against frequency for one or several :class:`FrequencyResponse`.

    Filled markers: stable orbits; open markers: unstable; colour by period multiple
    (period-1, and subharmonics n > 1); red crosses on the axis: failed points."""
    plt, ax, own = _axes(path, ax)
    if not isinstance(frfs, (list, tuple)):
        frfs = [frfs]
    colors = plt.get_cmap("tab10")
    markers = {"parallel": "o", "up": "^", "down": "v"}
    for frf in frfs:
        om = np.asarray(frf.omegas)
        amp = np.atleast_2d(frf.amplitude)
        for p in range(amp.shape[0]):
            a = amp[p] * 1e3
            ok = np.atleast_2d(frf.status)[p] == 0
            st = np.atleast_2d(frf.stable)[p]
            nn = np.atleast_2d(frf.period_multiple)[p]
            tag = label_prefix + frf.direction
            if frf.params:
                tag += " " + ", ".join(f"{k}={np.asarray(v)[p]:.3g}" for k, v in frf.params.items())
            ax.plot(om[ok], a[ok], "-", lw=0.6, color="0.6")
            for n in np.unique(nn[ok]):
                sel = ok & (nn == n)
                c = colors(int(n) - 1)
                mk = markers.get(frf.direction, "o")
                ax.plot(om[sel & st], a[sel & st], mk, ms=4, color=c,
                        label=f"{tag}: period-{n} stable")
                if (sel & ~st).any():
                    ax.plot(om[sel & ~st], a[sel & ~st], mk, ms=5, mfc="none", color=c,
                            label=f"{tag}: period-{n} unstable")
            if (~ok).any():
                ax.plot(om[~ok], np.zeros((~ok).sum()), "x", color="red",
                        label=f"{tag}: failed ({(~ok).sum()})")
    ax.set(xlabel="ω [rad/s]", ylabel="primary amplitude (half peak-to-peak) [mm]", title=title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    return _save(plt, ax, own, path)


BIFURCATION_STYLE = {"fold": ("o", "black", "fold"),
                     "period_doubling": ("s", "tab:red", "period doubling"),
                     "neimark_sacker": ("D", "tab:green", "Neimark–Sacker")}


def plot_branches(branches, path=None, *, ax=None, dof=None, field="amplitude", title="",
                  scale=1.0, unit=""):
    """Frequency–response curves from :func:`continuation`: stable parts solid, unstable
    parts dashed, one colour per period multiple, bifurcations marked (fold ●, period
    doubling ■, Neimark–Sacker ◆).  ``dof``: plot ``dof_<field>`` at that degree of freedom
    (default the system's observable, ``field`` = amplitude, rms or harmonic); ``scale``
    multiplies the values (1e3 for mm)."""
    plt, ax, own = _axes(path, ax)
    if not isinstance(branches, (list, tuple)):
        branches = [branches]
    colors = plt.get_cmap("tab10")
    seen = set()
    for br in branches:
        x = np.asarray(br.values)
        y = (np.asarray(getattr(br, field)) if dof is None else br.dof(dof, field)) * scale
        ok = np.asarray(br.status) == 0
        st = np.asarray(br.stable).astype(bool)
        c = colors((br.period_multiple - 1) % 10)
        # segment (i, i+1) solid when both ends are stable, dashed otherwise; runs of one
        # style drawn as one line
        seg = np.array([(ok[i] and ok[i + 1], bool(st[i] and st[i + 1]))
                        for i in range(len(x) - 1)]).reshape(-1, 2)
        i = 0
        while i < len(seg):
            j = i
            while j + 1 < len(seg) and tuple(seg[j + 1]) == tuple(seg[i]):
                j += 1
            valid, stable = seg[i]
            if valid:
                key = (br.period_multiple, bool(stable))
                ax.plot(x[i:j + 2], y[i:j + 2], "-" if stable else "--", color=c,
                        lw=1.4 if stable else 1.0,
                        label=None if key in seen else
                        f"period-{br.period_multiple} {'stable' if stable else 'unstable'}")
                seen.add(key)
            i = j + 1
        for b in br.bifurcations:
            mk, col, name = BIFURCATION_STYLE[b.kind]
            yb = b.amplitude if (dof is None and field == "amplitude") else np.interp(
                b.value, x[b.index:b.index + 2] if x[b.index] < x[b.index + 1]
                else x[b.index:b.index + 2][::-1],
                y[b.index:b.index + 2] if x[b.index] < x[b.index + 1]
                else y[b.index:b.index + 2][::-1])
            yb = yb * (scale if (dof is None and field == "amplitude") else 1.0)
            ax.plot([b.value], [yb], mk, color=col, ms=6, mfc="white" if not b.located else col,
                    label=None if b.kind in seen else name)
            seen.add(b.kind)
        if (~ok).any():
            ax.plot(x[~ok], np.zeros((~ok).sum()), "x", color="red")
    ax.set(xlabel=branches[0].parameter + (" [rad/s]" if branches[0].parameter == "omega"
                                           else ""),
           ylabel=(f"{field}" + (f" of {dof}" if dof else "") + (f" [{unit}]" if unit else "")),
           title=title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    return _save(plt, ax, own, path)


def plot_bifurcation_diagram(maps, path=None, *, ax=None, title="", scale=1.0, unit=""):
    """Stroboscopic bifurcation diagram from :func:`bifurcation_diagram`: the observable at
    ``t = kT`` over the statistics window, for every initial state, against ``ω``; periodic
    responses in colour by period multiple (a period-n orbit shows n points), the others
    grey."""
    plt, ax, own = _axes(path, ax)
    colors = plt.get_cmap("tab10")
    seen = set()
    for m in maps:
        for k in range(m.section.shape[0]):
            ok = int(m.steady.status[k]) == 0
            n = int(m.steady.period_multiple[k]) if ok else 0
            c = colors((n - 1) % 10) if ok else "0.6"
            lab = (f"period-{n}" if ok else "not periodic")
            ax.plot(np.full(m.section.shape[1], m.omega), m.section[k] * scale, ".", ms=1.5,
                    color=c, label=None if lab in seen else lab)
            seen.add(lab)
    ax.set(xlabel="ω [rad/s]", ylabel="observable at t = kT" + (f" [{unit}]" if unit else ""),
           title=title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, markerscale=4)
    return _save(plt, ax, own, path)
