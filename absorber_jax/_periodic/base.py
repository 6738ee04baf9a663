"""How a periodic orbit is found: the base classes of ``Shooting``, ``Marching`` and
``HarmonicBalance`` (objects that carry their own options, passed as ``method=``)."""

from __future__ import annotations

import abc

import equinox as eqx


class AbstractSteadyMethod(eqx.Module):
    """A way to find a periodic orbit of a system under a harmonic forcing.

    Generic code (``steady_state``, ``frequency_response``, ``tune``) talks to a method only
    through these members."""

    @abc.abstractmethod
    def initial_state(self, system, forcing):
        """The internal state the method starts from when no guess is given."""

    @abc.abstractmethod
    def solve(self, system, forcing, x0, cfg, *, with_floquet=True):
        """The [`SteadyState`][absorber_jax.SteadyState] from the *scaled* internal state ``x0``
        (one orbit solve, vmappable: nothing here retries or raises).  ``cfg`` holds the
        integration settings, to be passed on to [`orbit_map`][absorber_jax.orbit_map] and
        [`orbit_result`][absorber_jax.orbit_result], from which a method of one's own builds
        its orbit and its result."""

    @property
    @abc.abstractmethod
    def retry(self) -> bool:
        """Whether a failed solve is retried by marching then shooting."""

    @abc.abstractmethod
    def first_pass(self, budget):
        """The method for a sweep's vmapped pass, its iterations capped near ``budget`` so
        that a chunk does not run at the pace of its slowest lane (itself where it has no
        such cap)."""

    @abc.abstractmethod
    def giving_up(self, steps):
        """The method for a single solve that will be retried: it may stop early where its
        iterations wander (itself where it cannot)."""

    @abc.abstractmethod
    def resume(self, budget):
        """The method that finishes, from their best iterate, the points still iterating
        after ``first_pass(budget)``; None when there is nothing to resume."""


class AbstractSinglePassMethod(AbstractSteadyMethod):
    """A steady-state method whose iterations a sweep does not cap and that no solve
    retries (``Marching``, ``HarmonicBalance``): its first pass and its giving-up form are
    itself, and nothing is left to resume."""

    def first_pass(self, budget):
        return self

    def giving_up(self, steps):
        return self

    def resume(self, budget):
        return None


class AbstractChainingMethod(AbstractSteadyMethod):
    """A steady-state method that can also start a solve from a nearby orbit's period-map
    Jacobian (a sweep then hands each point its neighbour's orbit and Jacobian instead of
    solving the points independently)."""

    @property
    @abc.abstractmethod
    def chains(self) -> bool:
        """Whether sweeps chain this method's solves (it may depend on its options)."""

    @abc.abstractmethod
    def chain_jacobian(self, system, forcing, x0, cfg):
        """The scaled period-map Jacobian at the scaled state ``x0`` that a chain of solves
        starts from."""

    @abc.abstractmethod
    def solve_chained(self, system, forcing, x0, jacobian, cfg, *, with_floquet=True):
        """``(SteadyState, jacobian for the next point)`` from the scaled state ``x0`` with
        the scaled period-map Jacobian ``jacobian`` of a nearby orbit."""
