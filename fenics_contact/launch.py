"""The ``fenics-contact`` console script: ``cli.main`` behind a guard for Ctrl-C during start-up.

Importing the command line loads DOLFINx, UFL, FFCx and PETSc (seconds on a cold disk).  A Ctrl-C in
that time ends like an interrupted run: exit 130 and one line on stderr (nothing has been written yet),
not a KeyboardInterrupt traceback.  The signal is held until the import has finished: raised as
KeyboardInterrupt inside it, it can land in a Python callback of DOLFINx's C++ module initialisation,
which then aborts the whole process (SIGABRT, "terminate called after throwing an instance of
'nanobind::python_error'").  Only the import of this package itself comes before the guard: with the
binary wheel that is ``dolfinx_solver`` (a few tenths of a second); with any other DOLFINx it is
``dolfinx`` itself, which ``fenics_contact/__init__.py`` imports to check its version.
"""

import signal
import sys

__all__ = ["main"]


def main(argv: list[str] | None = None) -> int:
    # a Ctrl-C during the imports is recorded and acted on once they are done (see above); afterwards it
    # raises KeyboardInterrupt, as during the run (``cli.interruptible`` installs its own handlers), also
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
