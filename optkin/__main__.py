"""``python -m optkin``: the ``optkin`` command."""

from optkin.cli import console

if __name__ == "__main__":
    console()
