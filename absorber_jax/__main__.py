import sys

from ._io.cli import main

sys.exit(main())
