"""matplotlib figures of frequency responses."""

from __future__ import annotations

import numpy as np


def plot_frequency_response(frfs, path=None, *, title="", ax=None, label_prefix=""):
    """Primary amplitude against frequency for one or several :class:`FrequencyResponse`.

    Filled markers: stable orbits; open markers: unstable; colour by period multiple
    (period-1, and subharmonics n > 1); red crosses on the axis: failed points."""
    import matplotlib

    if path is not None:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if not isinstance(frfs, (list, tuple)):
        frfs = [frfs]
    own = ax is None
    if own:
        fig, ax = plt.subplots(figsize=(8, 4.5))
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
    if own and path is not None:
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)
    return ax
