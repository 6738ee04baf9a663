"""Continuation of periodic orbits in a parameter, with bifurcations."""
