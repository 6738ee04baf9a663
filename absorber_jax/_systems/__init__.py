"""Systems, structures, elements, forcing and parameters by name."""
