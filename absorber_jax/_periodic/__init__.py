"""Periodic steady states: shooting, marching, Floquet stability, sweeps, attractor maps."""
