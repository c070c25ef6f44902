"""The argparse command line: ``fenics-contact run``, ``fenics-contact examples``."""

import argparse
from pathlib import Path

from fenics_contact import __version__
from fenics_contact.cli.options import DEFAULT_H, METHODS
from fenics_contact.cli.signals import EXIT_CODES
from fenics_contact.examples import add_examples_parser
from fenics_contact.hybrid.iteration import ACCELERATIONS
from fenics_contact.hybrid.primal import DEFAULT_ALPHA, DEFAULT_ALPHA_MS
from fenics_contact.multiscale.cem import CEMOptions

__all__ = ["DESCRIPTION", "NOT_GIVEN", "build_parser"]

#: the first line of ``fenics-contact --help``
DESCRIPTION = "Command line: ``fenics-contact run …`` (one simulation with fields, plots and a summary)."
NOT_GIVEN = object()  #: an option the command line did not give (``build_parser(given_only=True)``)


def build_parser(*, given_only: bool = False) -> argparse.ArgumentParser:
    codes = "\n".join(f"  {code:<4} {meaning}" for code, meaning in EXIT_CODES.items())
    parser = argparse.ArgumentParser(prog="fenics-contact", description=DESCRIPTION)
    parser.add_argument("--version", action="version", version=f"fenics-contact {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser(
        "run", help="run one contact simulation and write fields, plots and a summary",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Run one contact simulation. Every option and file is checked before the mesh is built; the "
        "results are written into a temporary directory beside --out that replaces --out when the run ends "
        "(an earlier run there is replaced whole; an interrupted or failed run leaves --out as it was).",
        epilog=f"exit codes:\n{codes}\nEvery failure ends with one line on stderr.",
    )
    run.add_argument("--model", type=int, choices=(1, 2, 3), default=1,
                     help="built-in test model: 1 channels, 2 inclusions, 3 heterogeneous strip (loads in Ω₁)")
    run.add_argument("--method", choices=METHODS, default="primal", help="discretization / algorithm")
    run.add_argument("--h", type=int, help=f"fine size of the built-in mesh as 1/h (default {DEFAULT_H}); "
                     "not with --mesh, whose size is h = sqrt(2 x largest cell area) (1/n on an n x n grid)")
    run.add_argument("--H", type=int, default=16, help="coarse size / strip width as 1/H (e.g. 16); with --mesh the "
                     "coarse grid of squares of side 1/H over the bounding box (multiscale methods)")
    run.add_argument("--mesh", type=Path, help="a gmsh .msh file of planar triangles with the physical groups "
                     "Omega1, Omega2, Gamma_D, Gamma_C, gamma (checked against the contact problem); a file with "
                     "none of Omega1/Omega2/gamma gets Omega2 = the coarse cells along Gamma_C")
    run.add_argument("--coarse-groups", action="store_true",
                     help="with --mesh: the surface groups of the file are the coarse cells (a coarse partition of "
                     "your own) instead of the squares of side 1/H over the bounding box")
    run.add_argument("--alpha", help=f"primal Robin coefficient (default {DEFAULT_ALPHA}; primal-ms: "
                     f"{DEFAULT_ALPHA_MS}): a number or a product of numbers, h^p, sqrt-h and E (E_p: mean E at the "
                     "γ node) or Emin (the smallest E_p on γ), e.g. 1, h^-1/2, 2E*h^-1/2")
    run.add_argument("--accel", choices=ACCELERATIONS, default=None,
                     help="how the interface fixed point is solved: the interface Newton method (default: robust "
                     "on every tested model), Anderson acceleration, or none (the paper's plain update); under "
                     "mpiexec --method mixed defaults to anderson (its interface Newton is serial)")
    run.add_argument("--front-window", type=int, default=None, metavar="W",
                     help="with --accel newton: the contact Newton solves the contact equations locally on the W "
                     "Gamma_C unknowns on either side of every front of its next active set, the forces elsewhere "
                     "held (default 8; 0: off, the plain semismooth Newton). The same solution; 3-5 steps instead "
                     "of 8-11 where a near-rigid body rests on Gamma_C: README, 'Interface Newton'")
    run.add_argument("--tol", type=float, default=1e-6,
                     help="tolerance of the transmission residual (relative jump and traction imbalance on γ)")
    run.add_argument("--max-iterations", type=int, default=2000)
    run.add_argument("--delta", type=float, help="primal penalty δ (default 1e-3·h/E on Γ_C)")
    run.add_argument("--beta", help="mixed transmission coefficient β: sqrt-h (default) or a number")
    run.add_argument("--epsilon", type=float, help="mixed penalty ε (default 1e-3·h·E, the smallest E on Gamma_C)")
    run.add_argument("--E-high", type=float, help="E in the high-modulus pattern (default 1e3)")
    run.add_argument("--E-low", type=float, help="E elsewhere (default 1)")
    run.add_argument("--nu", type=float, default=0.35, help="Poisson ratio")
    run.add_argument("--E-map", type=Path, help="Young's modulus as a pixel array over the unit square "
                     "(.npy, or text/.csv readable by numpy.loadtxt; row 0 = bottom); replaces the model's E map; "
                     "every pixel the domain covers must be finite and > 0")
    run.add_argument("--layers", type=int, help=f"*-ms: oversampling layers m of the multiscale bases (default "
                     f"{CEMOptions().layers})")
    run.add_argument("--nbasis", type=int, help="*-ms: local spectral modes l per coarse cell (default 3)")
    run.add_argument("--min-gap", type=float,
                     help="mixed-ms: add Stage I modes on a coarse cell until the first one left out has "
                     "eigenvalue >= this (needed for nu -> 1/2; default 0.1; 0 keeps exactly --nbasis)")
    run.add_argument("--max-nbasis", type=int, help="mixed-ms: most Stage I modes per coarse cell (default 32)")
    run.add_argument("--cache-dir", type=Path, help="*-ms: directory for the offline data (reused when valid)")
    run.add_argument("--reference", action="store_true", help="also solve the monolithic problem and report e_u")
    run.add_argument("--out", default=None, help="output directory (default results/<model N, mesh or case file>-"
                     "<method>, e.g. results/model1-primal); replaced whole by the run, so it must be new, empty "
                     "or an earlier run's")
    run.add_argument("--no-plots", action="store_true", help="skip the PNG figures")
    run.add_argument("-v", "--verbose", action="store_true")
    # case files (issue 14): the problem from a TOML file; flags override it
    run.add_argument("--case", type=Path, help="a case file (TOML) describing the whole problem: mesh, materials, "
                     "loads, boundary conditions, obstacle and run options (cases/*.toml, README); the flags "
                     "override it: --h, --H, --mesh, --nu, --E-map, --model, --E-high, --E-low change its problem, "
                     "the others its run options")
    run.add_argument("--set", action="append", metavar="KEY=VALUE", help="with --case: replace one key of the "
                     "case file, VALUE in TOML syntax, e.g. --set mesh.refinement=0.5 --set "
                     "'obstacle.indentation=[1e-3, 2e-3]' (repeatable)")
    add_examples_parser(sub)
    if given_only:  # only the options the command line gives (the others absent): they override a case file
        run.set_defaults(**{dest: NOT_GIVEN for dest in vars(run.parse_args([])) if dest != "set"})  # append: a list
    return parser
