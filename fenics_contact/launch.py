"""The ``fenics-contact`` console script: ``cli.main`` behind a guard for Ctrl-C during start-up.

Importing the command line loads DOLFINx, UFL, FFCx and PETSc (seconds on a cold disk).  A Ctrl-C
in that time used to end with a KeyboardInterrupt traceback; here it ends like an interrupted run:
exit 130 and one line on stderr (nothing has been written yet).  Only the import of this package
itself (``dolfinx_solver``, a few tenths of a second) comes before the guard.
"""

import signal
import sys

__all__ = ["main"]


def main(argv: list[str] | None = None) -> int:
    # Ctrl-C raises KeyboardInterrupt here, as during the run (``cli._interruptible`` installs its own
    # handlers), also when the process inherited an ignored SIGINT (a background job of a script)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        from fenics_contact.cli import main as cli_main
    except KeyboardInterrupt:
        print("interrupted by SIGINT while starting up: nothing was written", file=sys.stderr)
        return 130
    return cli_main(argv)


if __name__ == "__main__":
    sys.exit(main())
