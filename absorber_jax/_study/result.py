"""A study's results: a labelled dataset, what the run computed, and summary figures."""

from __future__ import annotations

import equinox as eqx
import numpy as np


class StudyResult(eqx.Module):
    """The results of ``aj.study``.

    ``data``: an xarray Dataset over the designs' own dimensions (a grid's parameters, or
    ``design``/``sample`` with each parameter a coordinate) and the question's (``omega``,
    ``dof`` ...); every variable carries ``units`` and ``long_name``; the attributes hold
    the study's description, the system's parameters and its ``fingerprint``.
    ``computed``: the chunks this run computed (the others were read from the store);
    ``reused``: how many were; ``seconds``: this run's time; ``store``: the store's path.
    """

    data: object
    computed: tuple
    reused: int
    seconds: float
    store: str | None
    points_per_design: int

    @classmethod
    def from_store(cls, flat, axes, **kw):
        """The result from the store's flat dataset (dimension ``design``), presented in
        the designs' ``axes``."""
        return cls(data=_present(flat, axes), **kw)

    @property
    def rate(self) -> float:
        """Solves per second in this run (the chunks it computed)."""
        n = len(self.computed) * int(self.data.attrs["chunk"]) * self.points_per_design
        return n / self.seconds if self.seconds > 0 else float("nan")

    def failures(self) -> int:
        """How many points did not converge (``status`` not 0)."""
        if "status" not in self.data:
            return 0
        return int((np.asarray(self.data["status"]) != 0).sum())

    def summary(self) -> dict:
        """A JSON-ready summary: the study, its size, what this run computed, failures,
        and the peak over the design space (where the answer has one)."""
        d = self.data
        out = dict(study=d.attrs.get("study"), designs=_designs(d),
                   chunks_computed=len(self.computed), chunks_reused=self.reused,
                   seconds=round(self.seconds, 3), failed_points=self.failures(),
                   store=self.store)
        if "peak" in d:
            pk = np.asarray(d["peak"])
            if np.isfinite(pk).any():
                out["peak_min"] = float(np.nanmin(pk))
                out["peak_max"] = float(np.nanmax(pk))
                out["peak_mean"] = float(np.nanmean(pk))
        return out

    def to_netcdf(self, path):
        """The dataset as a netCDF file (needs netCDF4, h5netcdf or scipy)."""
        self.data.to_netcdf(path)

    def plot(self, path=None, variable="peak"):
        """The summary figure of ``variable`` (default the peak) over the design space:
        a line over one grid parameter, a map over two, or, for sampled designs, its
        distribution (histogram and empirical cumulative distribution).  Saved to
        ``path`` when given; returns the figure."""
        import matplotlib.pyplot as plt

        d = self.data
        if variable not in d:
            raise ValueError(f"plot: no variable {variable!r} in the study "
                             f"(has {sorted(d.data_vars)})")
        v = d[variable]
        extra = [x for x in v.dims if x not in _design_dims(d)]
        if extra:
            v = v.max(extra) if v.dtype.kind == "f" else v.isel({x: 0 for x in extra})
        label = f"{v.attrs.get('long_name', variable)} [{v.attrs.get('units', '')}]"
        dims = _design_dims(d)
        if dims in (("sample",), ("design",)):
            fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4))
            x = np.asarray(v, dtype=float)
            x = x[np.isfinite(x)]
            a1.hist(x, bins=max(10, int(np.sqrt(x.size))), color="tab:blue", alpha=0.8)
            a1.set_xlabel(label)
            a1.set_ylabel("designs")
            a2.step(np.sort(x), (np.arange(x.size) + 1) / max(x.size, 1), where="post",
                    color="tab:blue")
            if x.size:
                for q, style in ((0.5, "--"), (0.95, ":")):
                    xq = float(np.quantile(x, q))
                    for ax in (a1, a2):
                        ax.axvline(xq, color="k", ls=style, lw=1,
                                   label=f"{int(q * 100)} % quantile {xq:.4g}")
                a1.legend(fontsize=8)
            a2.set_xlabel(label)
            a2.set_ylabel("probability of not exceeding")
            a2.grid(True, alpha=0.3)
            fig.suptitle(f"{d.attrs.get('study')}: distribution over {x.size} designs")
        elif len(dims) == 1:
            fig, ax = plt.subplots(figsize=(7, 4))
            p = dims[0]
            ax.plot(np.asarray(d[p]), np.asarray(v, dtype=float), "o-", ms=3)
            ax.set_xlabel(f"{p} [{d[p].attrs.get('units', '')}]")
            ax.set_ylabel(label)
            ax.grid(True, alpha=0.3)
            ax.set_title(d.attrs.get("study"))
        else:
            fig, ax = plt.subplots(figsize=(7, 5))
            p, q = dims[:2]
            z = v.transpose(q, p, ...)
            if z.ndim > 2:
                z = z.max([x for x in z.dims if x not in (p, q)])
            m = ax.pcolormesh(np.asarray(d[p]), np.asarray(d[q]), np.asarray(z, dtype=float),
                              shading="nearest")
            fig.colorbar(m, ax=ax, label=label)
            ax.set_xlabel(f"{p} [{d[p].attrs.get('units', '')}]")
            ax.set_ylabel(f"{q} [{d[q].attrs.get('units', '')}]")
            ax.set_title(d.attrs.get("study"))
        fig.tight_layout()
        if path is not None:
            fig.savefig(path, dpi=120)
        return fig


def _design_dims(d):
    return tuple(d.attrs.get("design_dims", "design").split(","))


def _designs(d):
    return int(np.prod([d.sizes[x] for x in _design_dims(d)]))


def _present(flat, axes):
    """The store's flat ``design`` dimension reshaped into ``axes`` (a grid's parameters),
    or renamed (``sample``); the chunk flags dropped."""
    import pandas as pd

    ds = flat.drop_vars("chunk_done")
    ds = ds.drop_dims("chunk") if "chunk" in ds.dims else ds
    names = list(axes)
    if names == ["design"]:
        out = ds
    elif names == ["sample"]:
        out = ds.rename({"design": "sample"})
    else:
        import xarray as xr

        idx = pd.MultiIndex.from_arrays([np.asarray(ds[k].values) for k in names], names=names)
        out = ds.drop_vars(names + ["design"]).assign_coords(
            xr.Coordinates.from_pandas_multiindex(idx, "design")).unstack("design")
        for k in names:
            out[k].attrs = dict(flat[k].attrs)
        out = out.transpose(*names, ...)
    order = [k for k in flat.attrs.get("variables", "").split(",") if k in out]
    out = out[order + [k for k in out.data_vars if k not in order]]
    out.attrs = dict(flat.attrs, design_dims=",".join(names))
    return out
