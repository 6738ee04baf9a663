"""Scene files, the command line, plots and the paper reproduction."""
