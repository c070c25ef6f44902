"""The argparse command line: ``fenics-contact run``, ``check-mesh`` and ``examples``.

``run --help`` lists the options in groups (problem, method, iteration, multiscale, output), each
with its default as the code decides it: the fields of ``RunOptions``, the method catalogue
(``methods.METHODS``: the keyword defaults of each solve function and its multiscale options
dataclass), ``IterationOptions``/``InterfaceNewtonOptions`` and the built-in models' signature.
"""

import argparse
import inspect
from dataclasses import MISSING, fields
from pathlib import Path
from types import SimpleNamespace

from fenics_contact import __version__
from fenics_contact.cli.options import (
    DEFAULT_COARSE,
    DEFAULT_COARSE_3D_MS,
    DEFAULT_H,
    DEFAULT_H_3D,
    METHODS,
    MODEL_DEFAULTS,
    NBASIS_WORDS,
    RunOptions,
    method_default,
)
from fenics_contact.cli.signals import EXIT_CODES
from fenics_contact.examples import add_examples_parser
from fenics_contact.fem.amg import AUTO_AMG_DOFS, LINEAR_SOLVERS
from fenics_contact.fem.mixed import default_epsilon
from fenics_contact.fem.primal import default_penalty
from fenics_contact.hybrid.iteration import ACCELERATIONS, InterfaceNewtonOptions
from fenics_contact.methods import METHODS as CATALOGUE
from fenics_contact.methods import get_method

__all__ = ["DESCRIPTION", "NOT_GIVEN", "build_parser"]

#: the first line of ``fenics-contact --help``
DESCRIPTION = "Command line: ``fenics-contact run …`` (one simulation with fields, plots and a summary)."
NOT_GIVEN = object()  #: an option the command line did not give (``build_parser(given_only=True)``)
#: the default of each RunOptions field that has one
_RUN_DEFAULTS = {f.name: f.default for f in fields(RunOptions) if f.default is not MISSING}


def _shown(value) -> str:
    return "off" if value is None or value is False else f"{value:g}" if isinstance(value, float) else str(value)


def _nbasis(text: str) -> int | str:
    """--nbasis: a number, or one of ``NBASIS_WORDS`` (RunOptions says which methods take them)."""
    if text in NBASIS_WORDS:
        return text
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"an integer or one of {', '.join(NBASIS_WORDS)} expected, got {text!r}"
        ) from None


def _per_method(name: str) -> str:
    """The catalogue's default of a method option: one value, or each method's where they differ."""
    values = {m: method_default(m, name) for m in METHODS if name in CATALOGUE[m].flat_options()}
    if len({repr(v) for v in values.values()}) == 1:
        return _shown(next(iter(values.values())))
    return "; ".join(f"{m}: {_shown(v)}" for m, v in values.items())


def _accel_default() -> str:
    """The update each method runs when --accel is not given (``methods.Method.default_accel``), serial and on
    several ranks (the rule reads only the communicator's size)."""
    serial = {m: get_method(m).default_accel(SimpleNamespace(size=1)) for m in METHODS}
    ranks = {m: get_method(m).default_accel(SimpleNamespace(size=2)) for m in METHODS}
    text = (
        _shown(serial[METHODS[0]])
        if len(set(serial.values())) == 1
        else "; ".join(f"{m}: {v}" for m, v in serial.items())
    )
    changed = [f"--method {m}: {v}" for m, v in ranks.items() if v != serial[m]]
    return text + (f"; under mpiexec {', '.join(changed)}" if changed else "")


def _factor(function) -> str:
    return _shown(inspect.signature(function).parameters["factor"].default)


def _default(text: str) -> str:
    return f" (default: {text})"


def _add_problem_options(run: argparse.ArgumentParser) -> None:
    group = run.add_argument_group(
        "problem", "the body, its mesh, materials and loads: a built-in model, a mesh file or a case file"
    )
    group.add_argument(
        "--model",
        type=int,
        choices=(1, 2, 3, 4, 5),
        default=_RUN_DEFAULTS["model"],
        help="built-in test model: 1 channels, 2 inclusions, 3 heterogeneous strip (loads in Ω₁), 4 the 3D "
        "channel model (the unit cube, its strip Ω₂ of width 1/H; --method primal, or primal-ms on cubes of side 1/H), "
        "5 the 3D fibre composite (a gmsh block with stiff fibres along y, γ at x = 1 − 1/H cutting some of them; "
        "--method primal)" + _default(_shown(_RUN_DEFAULTS["model"])),
    )
    group.add_argument(
        "--case",
        type=Path,
        help="a case file (TOML) describing the whole problem: mesh, "
        "materials, loads, boundary conditions, obstacle and run options (cases/*.toml, README); the "
        "flags override it: --h, --H, --mesh, --nu, --E-map, --model, --E-high, --E-low change its "
        "problem, the others its run options" + _default("none: the built-in --model"),
    )
    group.add_argument(
        "--set",
        action="append",
        metavar="KEY=VALUE",
        help="with --case: replace one key of the "
        "case file, VALUE in TOML syntax, e.g. --set mesh.refinement=0.5 --set "
        "'obstacle.indentation=[1e-3, 2e-3]' (repeatable)" + _default("none"),
    )
    group.add_argument(
        "--mesh",
        type=Path,
        help="a gmsh .msh file of planar triangles (or of tetrahedra: volume groups) with the physical groups "
        "Omega1, Omega2, Gamma_D, Gamma_C, gamma (checked against the contact problem; "
        "fenics-contact check-mesh FILE checks it alone); a file with none of Omega1/Omega2/gamma "
        "gets Omega2 = the coarse cells along Gamma_C" + _default("none: the built-in unit square"),
    )
    group.add_argument(
        "--h",
        type=int,
        help=f"fine size of the built-in mesh as 1/h ({DEFAULT_H_3D} for the cube of --model 4 when not given); not "
        "with --mesh, whose size is h = sqrt(2 x largest area of a cell on Gamma_C) (1/n on an n x n grid)"
        + _default(_shown(DEFAULT_H)),
    )
    group.add_argument(
        "--H",
        type=int,
        help="coarse size / strip width as 1/H (the 3D models 4 and 5: the coarse cubes of side 1/H of primal-ms "
        f"and the strip, {DEFAULT_COARSE_3D_MS} for primal-ms when not given); with "
        "--mesh the coarse grid of squares of side 1/H over the bounding box (multiscale methods; a mesh of "
        "tetrahedra: the cubes of side 1/H that hold the Omega1 cells' centroids, for primal-ms only)"
        + _default(_shown(DEFAULT_COARSE)),
    )
    group.add_argument(
        "--coarse-groups",
        action="store_true",
        help="with --mesh: the surface groups of the file are the coarse cells (a coarse partition of "
        "your own) instead of the squares of side 1/H over the bounding box" + _default("off"),
    )
    group.add_argument(
        "--E-high",
        type=float,
        help="E in the high-modulus pattern of the built-in model" + _default(_shown(MODEL_DEFAULTS["E_high"])),
    )
    group.add_argument("--E-low", type=float, help="E elsewhere" + _default(_shown(MODEL_DEFAULTS["E_low"])))
    group.add_argument(
        "--nu", type=float, default=_RUN_DEFAULTS["nu"], help="Poisson ratio" + _default(_shown(_RUN_DEFAULTS["nu"]))
    )
    group.add_argument(
        "--E-map",
        type=Path,
        help="Young's modulus as a pixel array over the unit square "
        "(.npy, or text/.csv readable by numpy.loadtxt; row 0 = bottom); replaces the model's E map; "
        "every pixel the domain covers must be finite and > 0" + _default("none: the model's E"),
    )


def _add_method_options(run: argparse.ArgumentParser) -> None:
    group = run.add_argument_group("method", "the discretization, its penalty and transmission coefficient")
    group.add_argument(
        "--method",
        choices=(*METHODS, "primal-monolithic"),
        default=_RUN_DEFAULTS["method"],
        help="discretization / algorithm: "
        + "; ".join(f"{m} ({CATALOGUE[m].summary})" for m in METHODS)
        + "; primal-monolithic (two-body case files only: the penalized Newton on both bodies)"
        + _default(_RUN_DEFAULTS["method"]),
    )
    group.add_argument(
        "--alpha",
        help="primal Robin coefficient: a number or a product of numbers, h^p, sqrt-h and "
        "E (E_p: mean E at the γ node) or Emin (the smallest E_p on γ), e.g. 1, h^-1/2, 2E*h^-1/2; in a "
        "product h is h/L (L the body's size, the largest side of its bounding box) and the product is divided "
        "by L" + _default(_per_method("alpha")),
    )
    group.add_argument(
        "--delta",
        type=float,
        help="primal penalty δ" + _default(f"{_factor(default_penalty)}·h/E, the largest E on Gamma_C"),
    )
    group.add_argument(
        "--beta",
        help="mixed transmission coefficient β: sqrt-h (sqrt(h L)/E, the smallest E on Gamma_C, L the body's size) "
        "or a number" + _default(_per_method("beta")),
    )
    group.add_argument(
        "--epsilon",
        type=float,
        help="mixed penalty ε"
        + _default(f"{_factor(default_epsilon)}·(h/L)·E/L, the smallest E on Gamma_C, L the body's size"),
    )
    group.add_argument(
        "--reference", action="store_true", help="also solve the monolithic problem and report e_u" + _default("off")
    )
    group.add_argument(
        "--solver",
        choices=LINEAR_SOLVERS,
        help="linear solver of the primal monolithic reference: direct (MUMPS LU), amg (CG + smoothed-aggregation "
        f"AMG), auto (amg on a 3D mesh of {AUTO_AMG_DOFS:,} DOFs or more)" + _default("auto"),
    )


def _add_iteration_options(run: argparse.ArgumentParser) -> None:
    group = run.add_argument_group("iteration", "the interface iteration between Ω₁ and Ω₂ and when it stops")
    group.add_argument(
        "--accel",
        choices=ACCELERATIONS,
        default=None,
        help="how the interface fixed point is solved: the interface Newton method (robust on every "
        "tested model), Anderson acceleration, or none (the paper's plain update)" + _default(_accel_default()),
    )
    group.add_argument(
        "--front-window",
        type=int,
        default=None,
        metavar="W",
        help="with --accel newton: the contact Newton solves the contact equations locally on the W "
        "Gamma_C unknowns on either side of every front of its next active set, the forces elsewhere "
        "held (0: off, the plain semismooth Newton). The same solution; 3-5 steps instead of 8-11 "
        "where a near-rigid body rests on Gamma_C: README, 'Interface Newton'"
        + _default(_shown(InterfaceNewtonOptions().front_window)),
    )
    group.add_argument(
        "--tol",
        type=float,
        default=_RUN_DEFAULTS["tol"],
        help="tolerance of the transmission residual (relative jump and traction imbalance on γ)"
        + _default(_shown(_RUN_DEFAULTS["tol"])),
    )
    group.add_argument(
        "--max-iterations",
        type=int,
        default=_RUN_DEFAULTS["max_iterations"],
        help="most iterations" + _default(_shown(_RUN_DEFAULTS["max_iterations"])),
    )


def _add_multiscale_options(run: argparse.ArgumentParser) -> None:
    group = run.add_argument_group("multiscale", "the CEM-GMsFEM space in Ω₁ of primal-ms and mixed-ms")
    group.add_argument(
        "--layers",
        type=int,
        help="*-ms: oversampling layers m of the multiscale bases" + _default(_per_method("layers")),
    )
    group.add_argument(
        "--nbasis",
        type=_nbasis,
        help="*-ms: local spectral modes l per coarse cell, a number; primal-ms also takes rigid (as many as a "
        "coarse cell has rigid motions, 3 in 2D and 6 in 3D) and all (every local mode: with --layers covering "
        "Omega1, the fine space of Algorithm 1)" + _default(_per_method("nbasis")),
    )
    group.add_argument(
        "--min-gap",
        type=float,
        help="mixed-ms: add Stage I modes on a coarse cell until the first one left out has "
        "eigenvalue >= this (needed for nu -> 1/2; 0 keeps exactly --nbasis)" + _default(_per_method("min_gap")),
    )
    group.add_argument(
        "--max-nbasis",
        type=int,
        help="mixed-ms: most Stage I modes per coarse cell" + _default(_per_method("max_nbasis")),
    )
    group.add_argument(
        "--cache-dir",
        type=Path,
        help="*-ms: directory for the offline data (reused when valid)" + _default("none: no cache"),
    )


def _add_output_options(run: argparse.ArgumentParser) -> None:
    group = run.add_argument_group("output", "where the results go and what is written")
    group.add_argument(
        "--out",
        default=None,
        help="output directory; replaced whole by the run, so it must be new, "
        "empty or an earlier run's"
        + _default("results/<model N, mesh or case file>-<method>, e.g. results/model1-primal"),
    )
    group.add_argument("--no-plots", action="store_true", help="skip the PNG figures" + _default("off"))
    group.add_argument("-v", "--verbose", action="store_true", help="log at debug level" + _default("off"))


def _add_check_mesh_parser(subparsers) -> None:
    """``check-mesh``: a mesh or case file checked without a solve (``cli.check``)."""
    parser = subparsers.add_parser(
        "check-mesh",
        help="check a gmsh mesh or a case file without solving",
        description="Read a gmsh mesh (as run --mesh FILE reads it) or the mesh and problem of a case file (as run "
        "--case reads them), make every check a run makes before its first solve, and print what was found: the "
        "dimension, cells and vertices, the physical groups and the role of each, whether Omega1/Omega2/gamma "
        "were given or built, h and the contact cell size, whether gamma is straight, and which methods can run.",
        epilog="exit codes: 0 a run with the method could start; 2 it would be refused (the message says why)",
    )
    parser.add_argument("file", nargs="?", type=Path, metavar="FILE", help="a gmsh .msh file")
    parser.add_argument("--case", type=Path, help="a case file (TOML) instead of FILE" + _default("none"))
    parser.add_argument(
        "--set",
        action="append",
        metavar="KEY=VALUE",
        help="with --case: replace one key of the case file (as run --set)" + _default("none"),
    )
    parser.add_argument(
        "--method",
        choices=METHODS,
        default=None,
        help="the method the run would use" + _default(f"the case's [run] method, else {_RUN_DEFAULTS['method']}"),
    )
    parser.add_argument(
        "--H",
        type=int,
        default=None,
        help="with FILE: the coarse grid of squares of side 1/H over the bounding box, and the "
        "strip width when the file has no Omega1/Omega2/gamma (as run)" + _default(_shown(DEFAULT_COARSE)),
    )
    parser.add_argument(
        "--coarse-groups",
        action="store_true",
        help="with FILE: the surface groups of the file are the coarse cells (as run "
        "--coarse-groups)" + _default("off"),
    )


def build_parser(*, given_only: bool = False) -> argparse.ArgumentParser:
    codes = "\n".join(f"  {code:<4} {meaning}" for code, meaning in EXIT_CODES.items())
    parser = argparse.ArgumentParser(
        prog="fenics-contact",
        description=DESCRIPTION,
        epilog="fenics-contact COMMAND --help lists the options of a command",
    )
    parser.add_argument("--version", action="version", version=f"fenics-contact {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser(
        "run",
        help="run one contact simulation and write fields, plots and a summary",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Run one contact simulation. Every option and file is checked before the mesh is built; the "
        "results are written into a temporary directory beside --out that replaces --out when the run ends "
        "(an earlier run there is replaced whole; an interrupted or failed run leaves --out as it was).",
        epilog=f"exit codes:\n{codes}\nEvery failure ends with one line on stderr.",
    )
    _add_problem_options(run)
    _add_method_options(run)
    _add_iteration_options(run)
    _add_multiscale_options(run)
    _add_output_options(run)
    _add_check_mesh_parser(sub)
    add_examples_parser(sub)
    if given_only:  # only the options the command line gives (the others absent): they override a case file
        run.set_defaults(**{dest: NOT_GIVEN for dest in vars(run.parse_args([])) if dest != "set"})  # append: a list
    return parser
