"""The ``fenics-contact`` console script: ``cli.main`` behind a guard for Ctrl-C during start-up.

Importing the command line loads DOLFINx, UFL, FFCx and PETSc (seconds on a cold disk).  A Ctrl-C
in that time used to end with a KeyboardInterrupt traceback; here it ends like an interrupted run:
exit 130 and one line on stderr (nothing has been written yet).  The signal is held until the import
has finished: raised as KeyboardInterrupt inside it, it can land in a Python callback of DOLFINx's C++
module initialisation, which then aborts the whole process (SIGABRT, "terminate called after throwing an
instance of 'nanobind::python_error'": seen once in CI on 2026-12-02).  Only the import of this package
itself (``dolfinx_solver``, a few tenths of a second) comes before the guard.
"""

import signal
import sys

__all__ = ["main"]


def main(argv: list[str] | None = None) -> int:
    # a Ctrl-C during the imports is recorded and acted on once they are done (see above); afterwards it
    # raises KeyboardInterrupt, as during the run (``cli._interruptible`` installs its own handlers), also
    # when the process inherited an ignored SIGINT (a background job of a script)
    held: list[int] = []
    signal.signal(signal.SIGINT, lambda signum, frame: held.append(signum))
    try:
        from fenics_contact.cli import main as cli_main
    except KeyboardInterrupt:  # (raised by other means than the SIGINT handled here)
        held.append(signal.SIGINT)
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if held:
        print("interrupted by SIGINT while starting up: nothing was written", file=sys.stderr)
        return 130
    return cli_main(argv)


if __name__ == "__main__":
    sys.exit(main())
