"""``python -m optkin``: the ``optkin`` command."""

import sys

from optkin.cli import main

if __name__ == "__main__":
    sys.exit(main())
