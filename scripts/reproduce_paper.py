"""Reproduce the paper's figures (2, 4, 6, 7, 9–20) and check its conclusions.

    python scripts/reproduce_paper.py --out paper_figures [--quick]
"""

import sys

from absorber_jax._io.cli import main

if __name__ == "__main__":
    sys.exit(main(["reproduce-paper", *sys.argv[1:]]))
