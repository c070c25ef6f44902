"""Command line: ``fenics-contact run …`` (one simulation with fields, plots and a summary).

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
  130  interrupted by SIGINT (Ctrl-C), 143 by SIGTERM: --out is left as it was

Every failure ends with one line on stderr.
"""

import argparse
import logging
import math
import os
import re
import signal
import sys
import threading
import time
import typing
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, fields
from pathlib import Path
from typing import NamedTuple

import numpy as np
from mpi4py import MPI

from dolfinx import fem

from fenics_contact import __version__
from fenics_contact.errors import ConvergenceError, FenicsContactError, InputError
from fenics_contact.examples import add_examples_parser, run_examples_command
from fenics_contact.hybrid.iteration import ACCELERATIONS, InterfaceNewtonOptions, IterationOptions
from fenics_contact.hybrid.primal import DEFAULT_ALPHA, DEFAULT_ALPHA_MS
from fenics_contact.indentation import force_indentation
from fenics_contact.methods import HYBRID_METHODS, METHODS as CATALOGUE, get_method
from fenics_contact.io import (
    OutputDirectory,
    provenance,
    cell_function_of,
    cell_markers,
    check_output_target,
    stress_field,
    write_summary,
    write_vtx,
)
from fenics_contact.multiscale.cem import CEMOptions
from fenics_contact.multiscale.mixed_cem import DEFAULT_MAX_NBASIS, DEFAULT_MIN_GAP
from fenics_contact.paraview import Series, contact_grid, field_grid
from fenics_contact.plots import (
    hertz_curve_for,
    nodal_average,
    plot_cell_field,
    plot_contact,
    plot_displacement,
    plot_force_indentation,
    plot_history,
    plot_stress,
    render_deformed,
)
from fenics_contact.problem.case import Case, load_case, parse_override
from fenics_contact.problem.cell_groups import bounding_box
from fenics_contact.problem.geometry import ContactMesh, read_mesh, unit_square
from fenics_contact.problem.materials import check_poisson_ratio
from fenics_contact.problem.models import get_model, pixel_field
from fenics_contact.problem.problem import ContactProblem
from fenics_contact.problem.tags import Subdomain
from fenics_contact.problem.validation import contact_open_ends

__all__ = ["main", "build_parser", "run", "RunOptions", "EXIT_CODES", "Interrupted", "interruptible"]

log = logging.getLogger("fenics_contact")

METHODS = HYBRID_METHODS  #: the ``--method`` choices: Algorithms 1–4 (``methods.METHODS``)
DEFAULT_H = 64  #: 1/h of the built-in mesh when --h is not given

#: exit code -> meaning (``--help``, README)
EXIT_CODES = {
    0: "converged",
    2: "bad input (an option, a file or the mesh tags; nothing written)",
    3: "not converged: the transmission residual stayed above --tol (--max-iterations hit, or the interface Newton's "
       "corrections ran out; results written, \"converged\": false)",
    4: "numerical failure: Newton did not converge, non-finite values, a failed factorization (nothing written)",
    130: "interrupted by SIGINT (Ctrl-C); --out left as it was",
    143: "interrupted by SIGTERM; --out left as it was",
}
EXIT_BAD_INPUT, EXIT_NOT_CONVERGED, EXIT_NUMERICAL = 2, 3, 4
NOT_GIVEN = object()  #: an option the command line did not give (``build_parser(given_only=True)``)

#: what each option that only some methods use is (its message when another method is given it)
_METHOD_OPTION_HINTS = {
    "alpha": "the primal Robin coefficient; the mixed methods take --beta",
    "delta": "the primal penalty; the mixed methods take --epsilon",
    "beta": "the mixed transmission coefficient; the primal methods take --alpha",
    "epsilon": "the mixed penalty; the primal methods take --delta",
    "layers": "a multiscale option",
    "nbasis": "a multiscale option",
    "cache_dir": "the multiscale offline cache",
    "min_gap": "a mixed-ms option",
    "max_nbasis": "a mixed-ms option",
}
#: the options that only some methods use, and those methods (from the catalogue): giving one to another
#: method is refused, not ignored
_METHOD_OPTIONS: dict[str, tuple[tuple[str, ...], str]] = {
    name: (tuple(m for m in METHODS if name in CATALOGUE[m].flat_options()), hint)
    for name, hint in _METHOD_OPTION_HINTS.items()
}
#: the run tables of a case file and the methods that read each (``problem.case.RUN_TABLES``)
TABLE_METHODS: dict[str, tuple[str, ...]] = {
    "run": METHODS,
    "primal": tuple(m for m in METHODS if CATALOGUE[m].family == "primal"),
    "mixed": tuple(m for m in METHODS if CATALOGUE[m].family == "mixed"),
    "multiscale": tuple(m for m in METHODS if CATALOGUE[m].multiscale),
    "mixed-ms": ("mixed-ms",),
}
#: one factor of an α spelling (hybrid.transmission.robin_coefficient): a number [E or Emin], E, Emin, sqrt-h, h^p
_ALPHA_FACTOR = re.compile(
    r"^((?P<number>(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?)(Emin|E)?|Emin|E|sqrt-h|h\^\(?[+-]?\d+(\.\d*)?(/\d+)?\)?)$")
#: what a positive option is, for its message
_MEANING = {"delta": "the primal penalty δ", "epsilon": "the mixed penalty ε", "E_high": "a Young's modulus",
            "E_low": "a Young's modulus"}


def _flag(name: str) -> str:
    return "--" + name.replace("_", "-")


def _finite_positive(name: str, value) -> None:
    if value is not None and not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise InputError(f"{_flag(name)} ({_MEANING.get(name, 'a size')}) must be a finite number > 0, got {value!r}")


def _integer(name: str, value, minimum: int) -> None:
    if value is not None and not (isinstance(value, int) and value >= minimum):
        raise InputError(f"{_flag(name)} must be an integer >= {minimum}, got {value!r}")


def _check_alpha(alpha: str) -> None:
    for token in alpha.replace(" ", "").split("*"):
        match = _ALPHA_FACTOR.match(token)
        if match is not None and (match["number"] is None or 0 < float(match["number"]) < math.inf):
            continue
        raise InputError(f"cannot read the transmission coefficient --alpha {alpha!r}: give a number > 0 or a "
                         "product of numbers, h^p, sqrt-h and E (or Emin), e.g. 1, h^-1/2, 2E*h^-1/2, Emin*h^-1/2")


def _check_directory(flag: str, path: Path) -> None:
    """A directory that exists, or can be created: not a file, not below a file."""
    if not str(path).strip():
        raise InputError(f"{flag} must name a directory (got an empty string)")
    resolved = Path(path).resolve()
    if resolved.exists() and not resolved.is_dir():
        raise InputError(f"{flag} {path} exists and is a file, not a directory")
    existing = resolved
    while not existing.exists():
        existing = existing.parent
    if not existing.is_dir():
        raise InputError(f"{flag} {path} lies below {existing}, which is a file, not a directory")


def default_out(method: str, model: int, mesh: Path | None = None, case: Path | None = None) -> Path:
    """``results/<name>-<method>``, the name from the case file, else the mesh file, else the model: each problem
    and method its own directory, so runs (and ``make demo``'s) do not replace one another by default."""
    name = Path(case).stem if case is not None else Path(mesh).stem if mesh is not None else f"model{model}"
    return Path("results") / f"{name}-{method}"


def default_accel(method: str) -> str:
    """The method's default update (``methods.Method.default_accel``)."""
    return get_method(method).default_accel(MPI.COMM_WORLD)


@dataclass(frozen=True, slots=True)
class RunOptions:
    """What ``fenics-contact run`` was asked to do, validated on construction (InputError).

    ``None`` means "not given": the method's default is used, and an option that the chosen
    method does not use is refused rather than ignored. ``h`` is 1/h of the built-in mesh and
    is refused with ``mesh`` (a user mesh has its own size, ``geometry.mesh_size``).
    """

    model: int = 1
    method: str = "primal"
    h: int | None = None
    H: int = 16
    mesh: Path | None = None
    coarse_groups: bool = False
    alpha: str | None = None
    accel: str | None = None  #: None: "newton", or "anderson" for the mixed method on several ranks (default_accel)
    tol: float = 1e-6
    max_iterations: int = 2000
    front_window: int | None = None  #: the contact Newton's local front resolution (None: the default 8; 0: off)
    delta: float | None = None
    beta: str | None = None
    epsilon: float | None = None
    E_high: float | None = None
    E_low: float | None = None
    nu: float = 0.35
    E_map: Path | None = None
    layers: int | None = None
    nbasis: int | None = None
    min_gap: float | None = None
    max_nbasis: int | None = None
    cache_dir: Path | None = None
    reference: bool = False
    out: Path | None = None  #: None: results/<model N | mesh or case file stem>-<method> (default_out)
    plots: bool = True
    case: Path | None = None  #: the case file the problem came from (``--case``; see ``problem.case``)

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise InputError(f"unknown --method {self.method!r}; choose one of {METHODS}")
        get_model(self.model)  # InputError for an unknown model
        if self.accel is None:
            object.__setattr__(self, "accel", default_accel(self.method))
        if self.front_window is not None and self.accel != "newton":
            raise InputError(f"--front-window is an option of the interface Newton (--accel newton), not of --accel "
                             f"{self.accel}")
        if self.front_window is not None and (isinstance(self.front_window, bool)
                                              or not isinstance(self.front_window, (int, np.integer))
                                              or self.front_window < 0):
            raise InputError(f"--front-window must be an integer >= 0 (0: off), got {self.front_window!r}")
        for name, (methods, what) in _METHOD_OPTIONS.items():
            if getattr(self, name) is not None and self.method not in methods:
                raise InputError(f"{_flag(name)} does not apply to --method {self.method} (it is {what})")
        if self.coarse_groups and self.case is not None:
            raise InputError("--coarse-groups does not apply to --case: a case file's surface groups are material "
                             "groups; its coarse grid is the Cartesian grid of side 1/H over the bounding box "
                             "(mesh.H in the case file)")
        if self.coarse_groups and self.mesh is None:
            raise InputError("--coarse-groups takes the coarse cells from the surface groups of --mesh: give --mesh")
        if self.mesh is not None:
            if self.h is not None:
                raise InputError("--h sets the size of the built-in mesh; with --mesh the size comes from the file "
                                 "(h = sqrt(2 x largest cell area), reported in the summary): leave --h out")
            if not Path(self.mesh).is_file():
                raise InputError(f"--mesh {self.mesh} does not exist" if not Path(self.mesh).exists()
                                 else f"--mesh {self.mesh} is not a file")
        _integer("h", self.h, 2)
        _integer("H", self.H, 2)
        if self.mesh is None and self.n % self.H:
            raise InputError(f"--h {self.n} is not a multiple of --H {self.H}: the coarse grid must be a union of fine "
                             "cells")
        if self.mesh is None and self.H is not None and self.method.endswith("-ms") and self.n < 2 * self.H:
            raise InputError(f"--H {self.H} with --h {self.n}: a coarse cell of the multiscale methods must span at "
                             "least 2 fine cells per side (--H at most --h/2; H = h left a mixed-ms local problem "
                             "singular)")
        for name in ("delta", "epsilon", "E_high", "E_low"):
            _finite_positive(name, getattr(self, name))
        if self.E_map is not None:
            if self.E_high is not None or self.E_low is not None:
                raise InputError("--E-high/--E-low set the model's E map; --E-map replaces it: give one or the other")
            if not Path(self.E_map).is_file():
                raise InputError(f"--E-map {self.E_map} does not exist or is not a file")
        if not (isinstance(self.nu, (int, float)) and math.isfinite(self.nu)):
            raise InputError(f"--nu must be a finite number, got {self.nu!r}")
        check_poisson_ratio(self.nu)
        self.iteration_options()
        _integer("layers", self.layers, 0)
        _integer("nbasis", self.nbasis, 1)
        _integer("max_nbasis", self.max_nbasis, 1)
        if self.max_nbasis is not None and self.max_nbasis < self.value("nbasis"):
            raise InputError(f"--max-nbasis {self.max_nbasis} must be >= --nbasis {self.value('nbasis')}")
        if self.min_gap is not None and not (math.isfinite(self.min_gap) and self.min_gap >= 0):
            raise InputError(f"--min-gap must be a finite number >= 0, got {self.min_gap!r}")
        if self.alpha is not None:
            _check_alpha(self.alpha)
        if self.beta is not None:
            from fenics_contact.hybrid.mixed import transmission_coefficient

            transmission_coefficient(self.beta, 0.5)
        if self.cache_dir is not None:
            _check_directory("--cache-dir", self.cache_dir)
        out = self.out if self.out is not None else default_out(self.method, self.model, self.mesh, self.case)
        object.__setattr__(self, "out", check_output_target(out))

    @classmethod
    def from_namespace(cls, args: argparse.Namespace) -> "RunOptions":
        """From the parsed command line (``build_parser``)."""
        values = {f.name: getattr(args, f.name) for f in fields(cls) if f.name != "plots" and hasattr(args, f.name)}
        return cls(**values, plots=not args.no_plots)

    @property
    def n(self) -> int:
        """1/h of the built-in mesh."""
        return self.h if self.h is not None else DEFAULT_H

    def value(self, name: str):
        """The option, or the method's default when it was not given."""
        given = getattr(self, name)
        if given is not None:
            return given
        if name in ("E_high", "E_low"):
            return {"E_high": 1e3, "E_low": 1.0}[name]
        method = get_method(self.method)
        defaults = method.defaults()
        if name in defaults:
            return defaults[name]
        if method.cem_type is not None and name in (f.name for f in fields(method.cem_type)):
            return getattr(method.cem_type(), name)
        return None

    def method_options(self) -> dict:
        """The chosen method's options given on the command line (its defaults otherwise), for the catalogue."""
        flat = {name: getattr(self, name) for name in _METHOD_OPTIONS if getattr(self, name) is not None}
        if "min_gap" in flat:  # --min-gap 0: exactly --nbasis modes (the option's None)
            flat["min_gap"] = flat["min_gap"] or None
        return flat | {"options": self.iteration_options()}

    def iteration_options(self) -> IterationOptions:
        return IterationOptions(tol=self.tol, max_iterations=self.max_iterations, accel=self.accel,
                                newton=self.newton_options())

    def newton_options(self) -> InterfaceNewtonOptions:
        """The interface Newton's options (the front window of --front-window, else the default)."""
        window = InterfaceNewtonOptions().front_window if self.front_window is None else int(self.front_window)
        return InterfaceNewtonOptions(front_window=window)


def build_parser(*, given_only: bool = False) -> argparse.ArgumentParser:
    codes = "\n".join(f"  {code:<4} {meaning}" for code, meaning in EXIT_CODES.items())
    parser = argparse.ArgumentParser(prog="fenics-contact", description=__doc__.split("\n")[0])
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


# ---------------------------------------------------------------------------------------------
# case files (issue 14): the problem from --case FILE.toml, the flags overriding it
# ---------------------------------------------------------------------------------------------
#: RunOptions fields that describe the problem: with --case each one changes a key of the case
_PROBLEM_FLAGS = {"h": "mesh.h", "H": "mesh.H", "mesh": "mesh", "nu": "material.nu", "E_map": "material.E",
                  "model": "material.model", "E_high": "material.E-high", "E_low": "material.E-low"}


def options_from_arguments(args: argparse.Namespace, argv: list[str] | None = None) -> tuple[RunOptions, Case | None]:
    """The validated RunOptions of a command line and, with ``--case``, the Case it runs (InputError otherwise)."""
    if args.case is None:
        if args.set:
            raise InputError("--set changes a key of a case file: it needs --case FILE")
        return RunOptions.from_namespace(args), None
    given = {k: v for k, v in vars(build_parser(given_only=True).parse_args(argv)).items() if v is not NOT_GIVEN}
    case = load_case(args.case, _case_overrides(given))
    return case_run_options(case, given), case


def _case_overrides(given: dict) -> list[tuple[str, object]]:
    """The problem flags as case keys (``--h 16`` -> mesh.h = 16), then the ``--set`` items."""
    overrides = []
    for name, key in _PROBLEM_FLAGS.items():
        if name not in given:
            continue
        value = given[name]
        if name == "mesh":  # a mesh file replaces the [mesh] table
            value = {"file": str(Path(value).resolve())}
        elif name == "E_map":  # the flag's meaning: a pixel map over the unit square
            value = {"pixels": str(Path(value).resolve()), "extent": [0.0, 1.0, 0.0, 1.0]}
        overrides.append((key, value))
    return overrides + [parse_override(text) for text in given.get("set") or ()]


def _run_table_keys() -> dict[str, set[str]]:
    """The RunOptions fields each run table of a case file may set (the method options in their methods' table)."""
    general = {f.name for f in fields(RunOptions)} - set(_PROBLEM_FLAGS) - {"case"} - set(_METHOD_OPTIONS)
    keys = {table: set() for table in TABLE_METHODS} | {"run": general}
    for name, (methods, _) in _METHOD_OPTIONS.items():
        table = next((t for t, m in TABLE_METHODS.items() if t != "run" and set(m) == set(methods)), "run")
        keys[table].add(name)
    return keys


def case_run_options(case: Case, given: Mapping[str, object] = {}) -> RunOptions:
    """RunOptions from the case's run tables ([run] and the chosen method's), then the flags ``given`` (dest -> value).

    Each table is validated on its own (with a method that uses it), so a bad value is reported
    with its table even when the chosen method does not use it.
    """
    keys = _run_table_keys()
    names = {f.name for f in fields(RunOptions)}
    tables = {}
    for table, methods in TABLE_METHODS.items():
        values = {}
        for key, value in case.run[table].items():
            name = key.replace("-", "_")
            if name not in keys[table]:
                home = next((t for t, k in keys.items() if name in k), None)
                hint = f" ({key} belongs in [{home}])" if home else ""
                raise InputError(f"case {case.path}: unknown key '{table}.{key}'{hint}; the keys of [{table}] are "
                                 f"{sorted(k.replace('_', '-') for k in keys[table])}")
            values[name] = _run_value(case, f"{table}.{key}", name, value)
        probe = {"method": values.get("method", "primal") if table == "run" else methods[0]}
        if "out" in given:
            probe["out"] = given["out"]
        try:
            RunOptions(**(probe | values))
        except InputError as err:
            raise InputError(f"case {case.path}: [{table}] {err}") from None
        tables[table] = values
    method = given.get("method", tables["run"].get("method", "primal"))
    values = dict(tables["run"])
    for table, methods in TABLE_METHODS.items():
        if table != "run" and method in methods:
            values |= tables[table]
    values |= {k: v for k, v in given.items() if k in names and k not in _PROBLEM_FLAGS and k != "case"}
    if "no_plots" in given:
        values["plots"] = not given["no_plots"]
    return RunOptions(**values, case=case.path)


def _run_value(case: Case, key: str, name: str, value):
    """A run-table value of the type of its RunOptions field (TOML has no argparse to convert it)."""
    annotation = next(f.type for f in fields(RunOptions) if f.name == name)
    kind = next((t for t in (typing.get_args(annotation) or (annotation,)) if t is not type(None)), None)
    number = isinstance(value, (int, float)) and not isinstance(value, bool)
    if kind is str and name in ("alpha", "beta") and number:
        return repr(value)  # a coefficient may be written as a number
    ok = {bool: isinstance(value, bool), int: number and isinstance(value, int), float: number,
          str: isinstance(value, str), Path: isinstance(value, str)}.get(kind, True)
    if not ok:
        what = {bool: "true or false", int: "an integer", float: "a number", str: "a string",
                Path: "a directory name (a string)"}[kind]
        raise InputError(f"case {case.path}: {key} must be {what}, got {value!r}")
    return Path(value) if kind is Path else float(value) if kind is float else value


def _options_echo(options: RunOptions) -> dict:
    """The run options of a case run (case-file spelling), for the summary."""
    echo = {}
    for f in fields(RunOptions):
        if f.name in _PROBLEM_FLAGS or f.name == "case":
            continue
        if f.name in _METHOD_OPTIONS and options.method not in _METHOD_OPTIONS[f.name][0]:
            continue  # not used by this method
        value = options.value(f.name)
        echo[f.name.replace("_", "-")] = str(value) if isinstance(value, Path) else value
    return echo


def _at_open_ends(profile, ends: np.ndarray) -> list[list[float]]:
    """The open ends of Γ_C (``validation.open_ends``: x, y, end facet length) that ``profile``'s contact reaches:
    a contact node within one facet of the end (the mixed method's σ_c vanishes at the end node itself next to
    a traction-free side), whatever the order of the profile's nodes."""
    if not ends.size or profile.points is None or not np.any(profile.active):
        return []
    touching = profile.points[profile.active][:, :2]
    hits = []
    for x, y, length in ends:
        if np.min(np.linalg.norm(touching - [x, y], axis=1)) <= 1.01 * length:
            hits.append([float(x), float(y)])
    return hits


def _contact_summary(profile, ends: np.ndarray) -> dict:
    """Contact zone(s) of a profile for the summary: the span, each separate zone, open ends reached."""
    zone = profile.contact_zone()
    return {"contact_zone": [list(p) for p in zone] if zone else None,
            "contact_zones": [[list(a), list(b)] for a, b in profile.contact_zones()],
            "contact_at_open_end": _at_open_ends(profile, ends)}


def _curve_row(depth: float, direction: np.ndarray, profile, iterations: int, converged: bool, time_s: float,
               ends: np.ndarray) -> dict:
    return {"depth": float(depth), "force": float(profile.resultant @ direction), "normal_force": profile.force,
            "max_pressure": profile.max_pressure, **_contact_summary(profile, ends),
            "iterations": int(iterations), "converged": bool(converged), "time_s": time_s}


def _warn_open_ends(summary: dict, comm: MPI.Comm) -> None:
    """Warn (rank 0) when a solve's contact zone reaches an end of Γ_C where the boundary goes on straight."""
    hits = [("the run", summary["contact_at_open_end"])] if summary["contact_at_open_end"] else []
    steps = (summary.get("force_indentation") or {}).get("steps", [])
    hits += [(f"depth {s['depth']:g}", s["contact_at_open_end"]) for s in steps if s["contact_at_open_end"]]
    if hits and comm.rank == 0:
        where = "; ".join(f"{what} at {', '.join(f'({x:.6g}, {y:.6g})' for x, y in pts)}" for what, pts in hits)
        log.warning("the contact zone reaches an end of Gamma_C where the boundary goes on straight (%s): the "
                    "true zone is wider than Gamma_C, so the contact force and pressure are those of a contact "
                    "cut short by the tags, not of the body. Extend Gamma_C along that side.", where)


def _indentation_curve(options: RunOptions, case: Case, problem: ContactProblem, outcome, ends: np.ndarray,
                       out: Path, writes: bool) -> dict:
    """The force-indentation curve of the case's load steps (the last step is the run's depth), each step's
    fields and contact written into ``out`` as ParaView series (by the ranks with ``writes``).

    primal, mixed: ``indentation.force_indentation`` (warm starts, factorizations kept) with the
    run's penalty and transmission coefficient; primal-ms, mixed-ms: the same with the run's hybrid
    step, so the Ω₁ offline phase of the run serves every step.
    """
    spec = case.obstacle
    direction = np.asarray(spec.direction)
    if options.method in ("primal", "mixed"):
        if options.method == "primal":
            penalty = {"delta": outcome.summary["delta"], "alpha": options.value("alpha")}
        else:
            penalty = {"epsilon": outcome.summary["epsilon"], "beta": options.value("beta")}
    else:  # the run's step: its Ω₁ offline data, penalty and coefficients
        penalty = {"step": outcome.result.step}
    comm = problem.comm if writes else MPI.COMM_SELF
    fields, contact = Series(out, "fields", comm), Series(out, "contact", comm)
    primal = get_method(options.method).family == "primal"
    V = fem.functionspace(problem.cm.mesh, ("Lagrange", 1, (problem.dim,))) if primal else None

    def write_step(step, solver) -> None:
        state = (solver.glued(V),) if primal else solver.glued()[::-1]  # (collective over the offline ranks)
        if not writes:
            return
        fields.add(step.depth, _field_grid(problem, *state))
        contact.add(step.depth, contact_grid(step.profile, comm))

    curve = force_indentation(problem.with_(obstacle=spec.base()), options.method, spec.depths,
                              direction=direction, options=options.iteration_options(), on_step=write_step,
                              **penalty)
    rows = [_curve_row(s.depth, direction, s.profile, s.iterations, s.converged, s.time_s, ends) | {
        "transmission_residual": s.transmission_residual, "complementarity": s.complementarity._asdict(),
        "interface_newton_steps": s.interface_newton_steps}
        for s in curve.steps]
    return {"direction": direction.tolist(), "steps": rows}


# ---------------------------------------------------------------------------------------------
# inputs
# ---------------------------------------------------------------------------------------------
def load_pixel_map(path: Path) -> np.ndarray:
    """A 2D array of pixels from .npy or text (InputError if unreadable, empty or not 2D)."""
    try:
        if path.suffix == ".npy":
            values = np.load(path, allow_pickle=False)
        else:
            values = np.loadtxt(path, delimiter="," if path.suffix == ".csv" else None, ndmin=2)
    except (OSError, ValueError, EOFError) as err:
        raise InputError(f"cannot read a pixel array from {path}: {type(err).__name__}: {err}") from None
    try:
        values = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"--E-map {path} does not hold numbers (dtype {values.dtype})") from None
    if values.ndim != 2 or values.size == 0:
        raise InputError(f"--E-map {path} must hold a non-empty 2D array, got shape {values.shape}")
    return values


def check_pixel_modulus(values: np.ndarray, box: tuple[float, float, float, float], source: str) -> None:
    """Every pixel of the unit-square map that the box (x0, x1, y0, y1) covers is a finite E > 0."""
    ny, nx = values.shape
    x0, x1, y0, y1 = box
    i0, i1 = (int(np.clip(np.floor(x * nx), 0, nx - 1)) for x in (x0, x1))
    j0, j1 = (int(np.clip(np.floor(y * ny), 0, ny - 1)) for y in (y0, y1))
    covered = values[j0:j1 + 1, i0:i1 + 1]
    bad = ~(np.isfinite(covered) & (covered > 0))
    if np.any(bad):
        j, i = np.argwhere(bad)[0]
        raise InputError(f"{source}: {np.count_nonzero(bad)} pixels the domain covers are not a finite Young's "
                         f"modulus > 0 (first: row {j + j0}, column {i + i0}, value {float(covered[j, i])!r})")


def _model(options: RunOptions) -> tuple[ContactProblem, np.ndarray | None]:
    model = get_model(options.model, E_high=options.value("E_high"), E_low=options.value("E_low"), nu=options.nu)
    if options.E_map is None:
        return model, None
    values = load_pixel_map(options.E_map)
    if options.mesh is None:  # the built-in mesh covers the unit square: check before building it
        check_pixel_modulus(values, (0.0, 1.0, 0.0, 1.0), f"--E-map {options.E_map}")
    model = model.with_(youngs_modulus=pixel_field(values), description=f"E from {options.E_map.name}, "
                        f"nu={options.nu:g}")
    return model, values


def _mesh(options: RunOptions, comm: MPI.Comm = MPI.COMM_WORLD) -> ContactMesh:
    if options.mesh is not None:
        return read_mesh(options.mesh, H=None if options.coarse_groups else 1.0 / options.H, comm=comm)
    return unit_square(options.n, options.H, comm=comm)


def _replicated(options: RunOptions, comm: MPI.Comm) -> bool:
    """mixed-ms under MPI: every rank holds the whole mesh (the AW space is serial), the offline phase is shared."""
    return options.method == "mixed-ms" and comm.size > 1


def _bounding_box(cm: ContactMesh) -> tuple[float, float, float, float]:
    return bounding_box(cm.mesh)  # (an elementwise allreduce of arrays failed under MPI)


def _check_coarse_grid(cm: ContactMesh, options: RunOptions) -> None:
    """The multiscale methods need the coarse grid of squares of side H to be a union of fine cells."""
    cells = cm.cell_tags.find(Subdomain.OMEGA1)
    crossing = cm.comm.allreduce(int(np.count_nonzero(cm.coarse_cell[cells] < 0)), op=MPI.SUM)
    if crossing:
        raise InputError(f"--method {options.method} with --mesh {options.mesh}: {crossing} Omega1 cells cross the "
                         f"edges of the coarse grid of squares of side 1/{options.H} over the bounding box; the "
                         "multiscale methods need a mesh that resolves it (choose --H accordingly)")


def _check_case_coarse_grid(cm: ContactMesh, options: RunOptions, case: Case) -> None:
    """The multiscale methods need a coarse grid that the case's mesh resolves."""
    if cm.H is None:
        builtin = case.mesh.kind in ("hertz-block", "bulged-square")
        raise InputError(f"--method {options.method}: the mesh of case {case.path.name} ({case.mesh.kind}) has no "
                         "coarse grid; the multiscale methods need the unit-square mesh or a mesh file with mesh.H "
                         "(a coarse grid of squares of side 1/H that the mesh resolves)"
                         + (f" — the built-in {case.mesh.kind} mesh takes no mesh.H (its graded cells cross any "
                            "such grid): use --method primal or mixed on it, or a mesh file of your own that a "
                            "coarse grid resolves (mesh.H) or that carries its own coarse partition (README, 'Any "
                            "domain')" if builtin else ""))
    cells = cm.cell_tags.find(Subdomain.OMEGA1)
    crossing = cm.comm.allreduce(int(np.count_nonzero(cm.coarse_cell[cells] < 0)), op=MPI.SUM)
    if crossing:
        raise InputError(f"--method {options.method} with case {case.path.name}: {crossing} Omega1 cells cross the "
                         f"edges of the coarse grid of squares of side {cm.H:g} from the origin; the multiscale "
                         "methods need a mesh that resolves it (choose mesh.H accordingly)")


# ---------------------------------------------------------------------------------------------
# the two method families
# ---------------------------------------------------------------------------------------------
class _Outcome(NamedTuple):
    """What a method family hands back to ``run``: its result, summary entries and output writer."""

    result: object
    reference: object | None
    summary: dict
    write: Callable[[Path], None]


def _finite_or_none(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _field_grid(problem: ContactProblem, u, sigma=None):
    """The ParaView grid of a state: the P1 displacement ``u`` (primal; the stress from it), or the mixed
    stress ``sigma`` (DG P3: xx, xy, yy) and displacement ``u`` (DG P1, averaged at the vertices)."""
    fields, cm = problem.fields, problem.cm
    if sigma is None:
        s = _cell_array(stress_field(u, fields.lmbda, fields.mu))
        stress = np.column_stack([s[:, 0], s[:, 3], s[:, 1]])
    else:
        s = _cell_array(cell_function_of(sigma, name="sigma"))
        stress, u = np.column_stack([s[:, 0], s[:, 2], s[:, 1]]), nodal_average(u)
    return field_grid(u, stress, {"E": fields.E, "subdomain": cell_markers(cm.cell_tags, cm.mesh)}, fields.nu)


def _cell_array(fn) -> np.ndarray:
    """(local cells, components) of a DG0 function."""
    V = fn.function_space
    bs = V.dofmap.index_map_bs
    n = V.mesh.topology.index_map(V.mesh.topology.dim).size_local
    return fn.x.array.reshape(-1, bs)[V.dofmap.list[:n, 0]]


def _title(options: RunOptions, problem: ContactProblem) -> str:
    """The figures' name of the run: the case or mesh file, else the built-in model, and the method."""
    name = (f"case {Path(options.case).name}" if options.case is not None else
            f"mesh {Path(options.mesh).name}" if options.mesh is not None else f"model {options.model}")
    return f"{name}, {options.method}"


def _render_deformed(u, path: Path, options: RunOptions, problem: ContactProblem, profile) -> None:
    """The deformed body with the problem's own obstacle (a wall flush with Γ_C when it has none)."""
    wall = profile.points if problem.obstacle is None else None
    render_deformed(u, path, title=_title(options, problem), obstacle=problem.obstacle, wall=wall)


def _run_primal(options: RunOptions, problem: ContactProblem) -> _Outcome:
    """Algorithms 1 (primal) and 3 (primal-ms), with the monolithic primal reference."""
    method = get_method(options.method)
    flat = options.method_options()
    reference = (CATALOGUE["primal-monolithic"].solve(problem, delta=options.delta) if options.reference else None)
    result = method.solve(problem, **flat, reference=reference.u if reference is not None else None)
    ms = method.multiscale
    summary = {
        "alpha": options.value("alpha"),
        "delta": result.step.delta,
        "e_u": result.e_u,
        "e_energy": result.step.error_energy() if reference is not None else None,
        "penetration": result.profile.penetration,
        "max_tensile_sigma_c": float(np.max(result.profile.sigma_c, initial=0.0)),
        "layers": result.step.cem.layers if ms else None,
        "nbasis": result.step.cem.nbasis if ms else None,
        "offline_cache": result.step.omega1.cache_status if ms else None,
        # Λ, the smallest local eigenvalue left out (it falls like μ/(λ+2μ) as ν → ½, and with inclusions)
        "spectral_gap": _finite_or_none(result.step.omega1.spectral_gap) if ms else None,
    }
    fields, cm = problem.fields, problem.cm

    def write(out: Path) -> None:
        if not (out / "fields.pvd").exists():  # (load steps write their own series)
            Series(out, "fields", problem.comm).add(0.0, _field_grid(problem, result.u))
            Series(out, "contact", problem.comm).add(0.0, contact_grid(result.profile, problem.comm))
        if options.plots:
            plot_displacement(result.u, out / "displacement.png", title=f"({options.method} hybrid)")
            _render_deformed(result.u, out / "deformed.png", options, problem, result.profile)

    return _Outcome(result, reference, summary, write)


def _run_mixed(options: RunOptions, problem: ContactProblem, comm: MPI.Comm = MPI.COMM_SELF) -> _Outcome:
    """Algorithms 2 (mixed) and 4 (mixed-ms), with the monolithic mixed reference (serial).

    ``comm``: the ranks sharing the mixed-ms offline phase (each holds the whole mesh); the
    reference is then solved on rank 0 only, which alone reports the errors and writes.
    """
    method = get_method(options.method)
    ms = method.multiscale
    flat = options.method_options()
    reference = (CATALOGUE["mixed-monolithic"].solve(problem, epsilon=options.epsilon)
                 if options.reference and comm.rank == 0 else None)
    if reference is not None:
        reference.free()  # only its solution is used: the factors of the whole problem go now
    extra = {"offline_comm": comm} if ms else {}
    result = method.solve(problem, **flat, reference=reference, **extra)
    summary = {
        "beta": options.value("beta"),
        "beta_value": result.beta,
        "epsilon": result.epsilon,
        "e_sigma": result.e_sigma,
        "e_u": result.e_u,
        # mixed-ms: e_u is that of a coarse displacement (U_aux); e_u_post that of the fine one (README)
        "e_u_post": getattr(result, "e_u_post", None) if ms else None,
        "max_tensile_sigma_c": result.profile.max_tensile,
        "layers": result.step.cem.layers if ms else None,
        "nbasis": result.step.cem.nbasis if ms else None,
        "offline_cache": result.step.omega1.cache_status if ms else None,
        "stage_one_gap": result.step.omega1.spectral_gap if ms else None,
        "nbasis_per_cell": list(result.step.omega1.nbasis_range) if ms else None,
        "dim_X_ms": result.step.omega1.co.n_ms if ms else None,
    }
    fields, cm = problem.fields, problem.cm

    def write(out: Path) -> None:
        if not (out / "fields.pvd").exists():  # (load steps write their own series)
            Series(out, "fields", problem.comm).add(0.0, _field_grid(problem, result.u, result.sigma))
            Series(out, "contact", problem.comm).add(0.0, contact_grid(result.profile, problem.comm))
        write_vtx(out / "sigma.bp", result.sigma)
        write_vtx(out / "u.bp", result.u)
        if options.plots:
            plot_stress(result.sigma, out / "stress.png", title=f"({options.method} hybrid)")
            plot_displacement(result.u, out / "displacement.png", title=f"({options.method} hybrid)")
            _render_deformed(result.u, out / "deformed.png", options, problem, result.profile)

    return _Outcome(result, reference, summary, write)


# ---------------------------------------------------------------------------------------------
# one run
# ---------------------------------------------------------------------------------------------
def run(options: RunOptions, comm: MPI.Comm = MPI.COMM_WORLD, *, case: Case | None = None) -> int:
    """Run one simulation into ``options.out``; returns 0 (converged) or 3 (not converged), raises otherwise.

    ``case``: the problem from a case file (``options_from_arguments``); else the built-in model of
    the options. An ``Interrupted`` raised meanwhile carries ``output_complete``: whether ``--out``
    already holds the run.
    """
    model, pixels = _model(options) if case is None else (None, None)
    output = OutputDirectory(options.out, comm)
    try:
        with output:
            result, summary = _solve_and_write(options, comm, model, pixels, output, case)
    except Interrupted as stop:
        stop.output_complete = output.committed
        raise
    if not result.converged:
        capped = result.iterations >= options.max_iterations
        why = (f"the iteration hit --max-iterations {options.max_iterations}" if capped
               else f"stopped after {result.iterations} iterations (the Newton corrections ran out)")
        _fail(f"not converged: {why} (transmission residual {summary['transmission_residual']:.3e} > --tol "
              f"{options.tol:g}); results in {options.out} with \"converged\": false", comm)
        return EXIT_NOT_CONVERGED
    if not summary["converged"]:  # a load step of the force-indentation curve
        bad = [s for s in summary["force_indentation"]["steps"] if not s["converged"]]
        steps = ", ".join(f"depth {s['depth']:g} after {s['iterations']} iterations" for s in bad)
        _fail(f"not converged: the load step(s) at {steps} (--max-iterations {options.max_iterations}, --tol "
              f'{options.tol:g}); results in {options.out} with "converged": false', comm)
        return EXIT_NOT_CONVERGED
    log.info("converged after %d iterations; e_u = %s; active set %s; summary in %s",
             result.iterations, result.e_u, result.profile.active_interval(), options.out / "summary.json")
    return 0


def _solve_and_write(options: RunOptions, comm: MPI.Comm, model: ContactProblem | None, pixels: np.ndarray | None,
                     output: OutputDirectory, case: Case | None = None) -> tuple[object, dict]:
    """Mesh, solve, write everything into the staging directory and move it into place."""
    t0 = time.perf_counter()
    replicated = _replicated(options, comm)
    mesh_comm = MPI.COMM_SELF if replicated else comm  # replicated: every rank holds the whole mesh (mixed-ms)
    if case is None:
        cm = _mesh(options, mesh_comm)
        if pixels is not None and options.mesh is not None:
            check_pixel_modulus(pixels, _bounding_box(cm), f"--E-map {options.E_map}")
        if options.mesh is not None and options.method.endswith("-ms"):
            _check_coarse_grid(cm, options)
    else:
        case_mesh = case.build_mesh(mesh_comm)
        cm = case_mesh.cm
        model = case.problem(case_mesh)
        if options.method.endswith("-ms"):
            _check_case_coarse_grid(cm, options, case)
    problem = model.on(cm)
    problem.check_loaded()
    fields = problem.fields
    t_mesh = time.perf_counter() - t0
    name = f"model {options.model}" if case is None else f"case {case.path.name}"
    log.info("%s (%s), h = %.4g, H = %s, method %s, accel %s",
             name, model.description, cm.h, cm.H, options.method, options.accel)
    if get_method(options.method).family == "primal":
        outcome = _run_primal(options, problem)
    else:
        outcome = _run_mixed(options, problem, comm if replicated else MPI.COMM_SELF)
    result, reference = outcome.result, outcome.reference
    profile = result.profile
    ends = contact_open_ends(cm)  # (the open ends of Γ_C, for every solve's contact summary)
    writes = not replicated or comm.rank == 0  # replicated: rank 0 holds the whole run and writes it
    curve = (_indentation_curve(options, case, problem, outcome, ends, output.path, writes)
             if case and case.obstacle.steps else None)
    summary = {
        "method": options.method,
        "model": options.model if case is None else None,
        "mesh": str(options.mesh) if options.mesh is not None else None,
        "h": cm.h,
        "H": cm.H,
        "accel": options.accel,
        "front_window": options.newton_options().front_window if options.accel == "newton" else None,
        "iterations": result.iterations,
        "converged": result.converged and (curve is None or all(s["converged"] for s in curve["steps"])),
        "rel_tolerance": options.tol,
        # the relative change of the last two iterates (the paper's rule): not defined for the interface Newton,
        # which applies T once, to certify its solution
        "final_rel_change": float(result.history.rel_changes[-1]) if options.accel != "newton" else None,
        "transmission_residual": result.history.transmission_residual,
        "interface_newton_steps": result.history.newton_steps if options.accel == "newton" else None,
        **outcome.summary,
        "active_set": profile.active_interval(),
        "contact_force": profile.force,
        **_contact_summary(profile, ends),
        "max_contact_pressure": profile.max_pressure,
        # Ω₂'s semismooth Newton steps over the iteration (the interface Newton solves Ω₂ within its own steps)
        "newton_steps_total": (int(sum(r.info.get("newton", 0) for r in result.history.records))
                               if options.accel != "newton" else None),
        "dofs": result.dofs,
        "time_mesh_s": t_mesh,
        "time_offline_s": result.time_offline_s,
        "time_online_s": result.time_online_s,
        "time_interface_offline_s": result.history.time_offline_s,
        "time_error_evaluation_s": result.history.time_monitor_s,
        "time_reference_s": reference.time_s if reference is not None else None,
        "reference_newton_steps": reference.newton.steps if reference is not None else None,
        "reference_active_set": reference.profile.active_interval() if reference is not None else None,
        "mpi_ranks": comm.size,
        "provenance": provenance(),
        "force_indentation": curve,
        "case": case.to_dict() | {"run": _options_echo(options)} if case is not None else None,
    }
    _warn_open_ends(summary, comm)
    out = output.path
    writer = MPI.COMM_SELF if replicated else comm  # replicated: rank 0 holds the whole run and writes it
    if not replicated or comm.rank == 0:
        outcome.write(out)
        if options.plots:
            plot_cell_field(fields.E, out / "E.png", title=f"Young's modulus, {name}", log=True)
            if curve is not None:
                plot_force_indentation({options.method: curve}, out / "force_indentation.png", comm=writer)
            profiles = {f"{options.method} hybrid": profile}
            if reference is not None:
                profiles["monolithic"] = reference.profile
            (E_lo, E_hi), (nu_lo, nu_hi) = problem.contact_range("E"), problem.contact_range("nu")
            hertz = hertz_curve_for(problem.obstacle, profile.points, E_hi, nu_hi) \
                if (E_lo, nu_lo) == (E_hi, nu_hi) else None  # (Hertz: a homogeneous body at the contact)
            plot_contact(profiles, out / "contact.png", comm=writer, hertz=hertz)
            plot_history({f"{options.method}, {options.accel}": result.history}, out / "history.png", comm=writer,
                         tol=options.tol)
        write_summary(out, summary, writer)
    output.commit()
    return result, summary


# ---------------------------------------------------------------------------------------------
# the command
# ---------------------------------------------------------------------------------------------
class Interrupted(BaseException):
    """SIGINT or SIGTERM arrived (raised by the handlers of ``interruptible``)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


#: a signal that arrives inside a ``__del__`` is raised again this much later (s)
DEFERRED_SIGNAL_S = 0.05


def _in_finalizer(frame) -> bool:
    while frame is not None:
        if frame.f_code.co_name == "__del__":
            return True
        frame = frame.f_back
    return False


@contextmanager
def interruptible() -> Iterator[list[int]]:
    """SIGINT and SIGTERM raise ``Interrupted`` (so that cleanup runs); the previous handlers come back after.

    Python ignores an exception raised in a ``__del__`` (it prints "Exception ignored in ...") and goes on: a
    SIGTERM that arrived while DOLFINx freed a vector was lost and the run went on to exit 0.  A signal that
    arrives in a finalizer is therefore sent again ``DEFERRED_SIGNAL_S`` later (a timer thread; no SIGALRM, so
    a caller's alarms are left alone), and it is kept in the yielded list until it has been raised: a signal
    still listed when the block ends (it landed in the last finalizers) is the caller's to report.
    """
    pending: list[int] = []
    timers: list[threading.Timer] = []

    def handler(signum, frame):
        if _in_finalizer(frame):
            pending.append(signum)
            timer = threading.Timer(DEFERRED_SIGNAL_S, os.kill, (os.getpid(), signum))
            timer.daemon = True
            timers.append(timer)
            timer.start()
            return
        pending.clear()
        raise Interrupted(signum)

    main_thread = threading.current_thread() is threading.main_thread()
    signals = (signal.SIGINT, signal.SIGTERM) if main_thread else ()
    previous = {s: signal.signal(s, handler) for s in signals}
    try:
        yield pending
    finally:
        for timer in timers:
            timer.cancel()
        for s, h in previous.items():
            signal.signal(s, h)


class _RankZero(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        return MPI.COMM_WORLD.rank == 0


class _BelowWarning(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        return record.levelno < logging.WARNING


def _setup_logging(verbose: bool) -> None:
    """The progress log on stdout, warnings on stderr prefixed ``warning:``, rank 0 only; a failure ends with one
    line on stderr (``_fail``), the last."""
    out = logging.StreamHandler(sys.stdout)
    out.addFilter(_RankZero())
    out.addFilter(_BelowWarning())
    out.setFormatter(logging.Formatter("%(message)s"))
    warn = logging.StreamHandler(sys.stderr)
    warn.setLevel(logging.WARNING)
    warn.addFilter(_RankZero())
    warn.setFormatter(logging.Formatter("warning: %(message)s"))
    root = logging.getLogger("fenics_contact")
    root.handlers[:] = [out, warn]
    root.setLevel(logging.DEBUG if verbose else logging.INFO)
    root.propagate = False


def _fail(message: str, comm: MPI.Comm = MPI.COMM_WORLD) -> None:
    """One line on stderr (rank 0)."""
    if comm.rank == 0:
        print(" ".join(str(message).split()), file=sys.stderr, flush=True)


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)  # argparse errors exit with 2 (bad input) too
    if args.command == "examples":
        return run_examples_command(args)
    _setup_logging(getattr(args, "verbose", False))
    comm = MPI.COMM_WORLD
    out = getattr(args, "out", None)
    with interruptible() as pending:
        try:
            options, case = options_from_arguments(args, argv)
            out = options.out
            code = run(options, comm, case=case)
        except Interrupted as stop:
            where = (f"the results in {out} are complete" if getattr(stop, "output_complete", False)
                     else f"{out} left as it was (no partial output)")
            _fail(f"interrupted by {stop}: {where}", comm)
            return 128 + stop.signum
        except ConvergenceError as err:
            _fail(f"numerical failure: {err}", comm)
            return EXIT_NUMERICAL
        except FenicsContactError as err:  # InputError, MeshTagError
            _fail(f"error: {err}", comm)
            return EXIT_BAD_INPUT
    if pending:  # a signal landed in the last finalizers of a run that had ended: its results are written
        signum = pending[-1]
        _fail(f"interrupted by {signal.Signals(signum).name}: the results in {out} are complete", comm)
        return 128 + signum
    return code


if __name__ == "__main__":
    sys.exit(main())
