"""``python -m optkin``: the ``optkin`` command."""

import sys

if __name__ == "__main__":
    from optkin._exit import quiet_interrupts

    quiet_interrupts()  # a Ctrl-C while the command line itself is importing: status 130
    try:
        from optkin.cli import console
    except KeyboardInterrupt:
        sys.stderr.write("optkin: interrupted\n")
        sys.exit(130)
    quiet_interrupts(False)
    console()
