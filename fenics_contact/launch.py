"""The ``fenics-contact`` console script: ``cli.main`` behind a guard for Ctrl-C during start-up.

Importing the command line loads DOLFINx, UFL, FFCx and PETSc (seconds on a cold disk).  A Ctrl-C
in that time used to end with a KeyboardInterrupt traceback; here it ends like an interrupted run:
exit 130 and one line on stderr (nothing has been written yet).  Only the import of this package
itself (``dolfinx_solver``, a few tenths of a second) comes before the guard.
"""

import sys

__all__ = ["main"]


def main(argv: list[str] | None = None) -> int:
    try:
        from fenics_contact.cli import main as cli_main
    except KeyboardInterrupt:
        print("interrupted by SIGINT while starting up: nothing was written", file=sys.stderr)
        return 130
    return cli_main(argv)


if __name__ == "__main__":
    sys.exit(main())
