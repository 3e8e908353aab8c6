"""``python -m optkin``: the ``optkin`` command."""

import sys

if __name__ == "__main__":
    try:
        from optkin.cli import console
    except KeyboardInterrupt:  # a Ctrl-C while the command line itself is importing
        sys.stderr.write("optkin: interrupted\n")
        sys.exit(130)
    console()
