"""Command line: ``fenics-contact run …`` (one simulation with fields, plots and a summary).

``fenics-contact check-mesh FILE`` (or ``--case CASE.toml``) reads and checks a mesh as a run
would, without a solve (``cli.check``); ``fenics-contact examples DIR`` copies the example files.
The modules: ``options`` (RunOptions), ``parser`` (argparse), ``cases`` (case files),
``solve`` (one run: the solve and load steps), ``outputs`` (summary entries, grids), ``check``
(check-mesh), ``signals`` (SIGINT/SIGTERM, exit codes), ``command`` (``main``); ``pair`` and
``pair_outputs``: the run and the outputs of a case of two deformable bodies (a case with ``[pair]``).

A run goes: parse → one validated ``RunOptions`` (every option and file checked before
any mesh is built) → inputs (E map) → output staging directory → mesh (a user mesh is
validated against the contact problem) → solve → write into the staging directory →
move it into place. Exit codes:

  0    converged
  2    bad input: an option, a file (--mesh, --E-map, --out, --cache-dir) or a mesh whose
       tags contradict the problem; nothing is written
  3    not converged: the transmission residual stayed above --tol (the iteration hit
       --max-iterations, or the interface Newton's corrections ran out); the results are written with
       "converged": false
  4    numerical failure: Newton did not converge, non-finite values, a failed
       factorization; nothing is written
  5    the results could not be written (too little space for them, a failed write): --out is
       left as it was
  130  interrupted by SIGINT (Ctrl-C), 143 by SIGTERM: --out is left as it was

Every failure ends with one line on stderr.
"""

from fenics_contact.cli.cases import case_run_options, options_from_arguments
from fenics_contact.cli.check import check_mesh
from fenics_contact.cli.command import main
from fenics_contact.cli.options import DEFAULT_H, METHODS, TABLE_METHODS, RunOptions, default_accel, default_out
from fenics_contact.cli.parser import NOT_GIVEN, build_parser
from fenics_contact.cli.signals import (
    EXIT_BAD_INPUT,
    EXIT_CODES,
    EXIT_NOT_CONVERGED,
    EXIT_NUMERICAL,
    EXIT_WRITE,
    Interrupted,
    interruptible,
)
from fenics_contact.cli.solve import check_pixel_modulus, load_pixel_map, run

_interruptible = interruptible  #: the name tests/test_interrupt.py imports

__all__ = [
    "DEFAULT_H",
    "EXIT_BAD_INPUT",
    "EXIT_CODES",
    "EXIT_NOT_CONVERGED",
    "EXIT_NUMERICAL",
    "EXIT_WRITE",
    "METHODS",
    "NOT_GIVEN",
    "TABLE_METHODS",
    "Interrupted",
    "RunOptions",
    "build_parser",
    "case_run_options",
    "check_mesh",
    "check_pixel_modulus",
    "default_accel",
    "default_out",
    "interruptible",
    "load_pixel_map",
    "main",
    "options_from_arguments",
    "run",
]
