"""``main``: parse, run the subcommand (run, check-mesh, examples), and turn its ending into an exit code and one
line on stderr."""

import signal

from mpi4py import MPI

from fenics_contact.cli.cases import options_from_arguments
from fenics_contact.cli.check import check_mesh
from fenics_contact.cli.parser import build_parser
from fenics_contact.cli.signals import (
    EXIT_BAD_INPUT,
    EXIT_NUMERICAL,
    EXIT_WRITE,
    Interrupted,
    _fail,
    _setup_logging,
    end_every_rank,
    interruptible,
    share_rank_zero,
)
from fenics_contact.cli.solve import run
from fenics_contact.errors import ConvergenceError, FenicsContactError, OutputError
from fenics_contact.examples import run_examples_command
from fenics_contact.io import check_jit_cache

__all__ = ["main"]


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)  # argparse errors exit with 2 (bad input) too
    if args.command == "examples":
        return run_examples_command(args)
    _setup_logging(getattr(args, "verbose", False))
    comm = MPI.COMM_WORLD
    out = getattr(args, "out", None)
    if comm.size > 1:
        share_rank_zero(comm)
    with interruptible() as pending:
        try:
            if args.command == "check-mesh":
                code = check_mesh(args, comm)
            else:
                options, case = options_from_arguments(args, argv)
                check_jit_cache()
                out = options.out
                code = run(options, comm, case=case)
        except Interrupted as stop:
            where = (
                "nothing was written"
                if args.command == "check-mesh"
                else f"the results in {out} are complete"
                if getattr(stop, "output_complete", False)
                else f"{out} left as it was (no partial output)"
            )
            if comm.size > 1:  # the other ranks may wait for this one in a collective operation
                end_every_rank(f"interrupted by {stop}: {where}", stop.signum, comm)
            _fail(f"interrupted by {stop}: {where}", comm)
            return 128 + stop.signum
        except ConvergenceError as err:
            _fail(f"numerical failure: {err}", comm)
            return EXIT_NUMERICAL
        except OutputError as err:
            _fail(f"error: {err}; {out} left as it was", comm)
            return EXIT_WRITE
        except FenicsContactError as err:  # InputError, MeshTagError
            _fail(f"error: {err}", comm)
            return EXIT_BAD_INPUT
        except SystemExit as stop:  # user code run by the case (a python field) called sys.exit
            _fail(
                f"error: code run by the case called sys.exit({stop.code!r}) and would have ended the run "
                f"unfinished: {out} left as it was",
                comm,
            )
            return EXIT_BAD_INPUT
    if pending:  # a signal landed in the last finalizers of a run that had ended: its results are written
        signum = pending[-1]
        where = "nothing was written" if args.command == "check-mesh" else f"the results in {out} are complete"
        _fail(f"interrupted by {signal.Signals(signum).name}: {where}", comm)
        return 128 + signum
    return code
