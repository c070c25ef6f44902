"""The ``fenics-contact`` console script: ``cli.main`` behind a guard for SIGINT and SIGTERM during start-up.

Importing the command line loads DOLFINx, UFL, FFCx and PETSc (seconds on a cold disk).  A Ctrl-C or a
SIGTERM in that time ends like an interrupted run: exit 130 / 143 and one line on stderr (nothing has been
written yet), not a KeyboardInterrupt traceback.  The signal is held until the import has finished: raised
as KeyboardInterrupt inside it, it can land in a Python callback of DOLFINx's C++ module initialisation,
which then aborts the whole process (SIGABRT, "terminate called after throwing an instance of
'nanobind::python_error'").  Only the import of this package itself comes before the guard: with the
binary wheel that is ``dolfinx_solver`` (a few tenths of a second); with any other DOLFINx it is
``dolfinx`` itself, which ``fenics_contact/__init__.py`` imports to check its version.

PETSc's own signal handler is switched off (``-no_signal_handler`` in ``PETSC_OPTIONS``): it would catch
SIGTERM and SIGPIPE and end the process by ``MPI_Abort`` with seven lines of "PETSC ERROR" (exit 15, or
SIGPIPE killing a run whose progress log went to a closed pipe, its results unwritten).  The handlers of
the command line (``cli.signals``) take SIGINT and SIGTERM; SIGPIPE stays ignored, as Python leaves it, so
that a closed stdout is an error the progress log handles.
"""

import os
import signal
import sys

__all__ = ["main"]

#: PETSc's option that leaves the signals to the command line
NO_PETSC_SIGNAL_HANDLER = "-no_signal_handler"


def _without_petsc_signal_handler() -> None:
    """Ask PETSc (initialised later, by the import of the command line) not to install its signal handler."""
    options = os.environ.get("PETSC_OPTIONS", "")
    if NO_PETSC_SIGNAL_HANDLER not in options.split():
        os.environ["PETSC_OPTIONS"] = f"{options} {NO_PETSC_SIGNAL_HANDLER}".strip()


def main(argv: list[str] | None = None) -> int:
    # a SIGINT or SIGTERM during the imports is recorded and acted on once they are done (see above); afterwards
    # SIGINT raises KeyboardInterrupt and SIGTERM ``Interrupted``, as during the run (``cli.interruptible``
    # installs its own handlers), also when the process inherited an ignored SIGINT (a background job)
    _without_petsc_signal_handler()
    held: list[int] = []
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda signum, frame: held.append(signum))
    try:
        from fenics_contact.cli import main as cli_main
        from fenics_contact.cli.signals import Interrupted, raise_interrupted
    except KeyboardInterrupt:  # (raised by other means than the SIGINT handled here)
        held.append(signal.SIGINT)
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if held:
        message = f"interrupted by {signal.Signals(held[0]).name} while starting up: nothing was written"
        _end(message, held[0])
        return 128 + held[0]
    # (a PETSc initialised before the guard, e.g. by a DOLFINx that imports petsc4py, took these signals)
    signal.signal(signal.SIGTERM, raise_interrupted)
    signal.signal(signal.SIGPIPE, signal.SIG_IGN)
    try:
        return cli_main(argv)
    except Interrupted as stop:  # before the run's own handlers (parsing the arguments)
        _end(f"interrupted by {stop} while starting up: nothing was written", stop.signum)
        return 128 + stop.signum


def _end(message: str, signum: int) -> None:
    """Print ``message``; under MPI end every rank (``cli.signals.end_every_rank``: others wait for this one)."""
    from mpi4py import MPI

    if MPI.Is_initialized() and MPI.COMM_WORLD.size > 1:
        from fenics_contact.cli.signals import end_every_rank

        end_every_rank(message, signum)
    print(message, file=sys.stderr)


if __name__ == "__main__":
    sys.exit(main())
