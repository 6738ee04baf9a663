"""Root finders that wrap an optimistix one (equinox's advice: wrap library classes rather
than subclass concrete ones, as ``optx.BestSoFarRootFinder`` does)."""

from __future__ import annotations

import equinox as eqx
import optimistix as optx


class AbstractWrappedRootFinder(optx.AbstractRootFinder):
    """A root finder around ``solver``, whose tolerances and norm it reports as its own; a
    concrete one gives ``init``, ``step``, ``terminate`` and ``postprocess``, changing what
    it wraps where it needs to."""

    solver: eqx.AbstractVar[optx.AbstractRootFinder]

    @property
    def rtol(self):
        return self.solver.rtol

    @property
    def atol(self):
        return self.solver.atol

    @property
    def norm(self):
        return self.solver.norm
