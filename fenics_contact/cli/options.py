"""``RunOptions``: what ``fenics-contact run`` was asked to do, every option checked before a mesh is built.

``None`` in a field means "not given": the method's default (``methods.Method.defaults``, the
multiscale option dataclasses) is used, and an option the chosen method does not use is refused.
"""

import argparse
import inspect
import math
import re
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fenics_contact.errors import InputError
from fenics_contact.fem.amg import LINEAR_SOLVERS
from fenics_contact.hybrid.iteration import InterfaceNewtonOptions, IterationOptions
from fenics_contact.hybrid.mixed import transmission_coefficient
from fenics_contact.io import check_output_target, check_outside_output
from fenics_contact.methods import HYBRID_METHODS, get_method
from fenics_contact.methods import METHODS as CATALOGUE
from fenics_contact.multiscale.cem.options import ALL_MODES, RIGID_MOTIONS
from fenics_contact.problem.composite3d import MODEL_COMPOSITE_3D
from fenics_contact.problem.materials import check_poisson_ratio
from fenics_contact.problem.models import MODELS_3D, get_model, model_1
from fenics_contact.problem.validation import METHODS_3D

__all__ = [
    "DEFAULT_H",
    "DEFAULT_H_3D",
    "DEFAULT_COARSE",
    "DEFAULT_COARSE_3D_MS",
    "METHODS",
    "NBASIS_WORDS",
    "MODEL_DEFAULTS",
    "TABLE_METHODS",
    "RunOptions",
    "default_accel",
    "default_out",
    "method_default",
]

METHODS = HYBRID_METHODS  #: the ``--method`` choices: Algorithms 1–4 (``methods.METHODS``)
DEFAULT_H = 64  #: 1/h of the built-in mesh when --h is not given
DEFAULT_H_3D = 16  #: 1/h of the built-in cube of the 3D models (--model 4, 5) when --h is not given
DEFAULT_COARSE = 16  #: 1/H (coarse size / strip width) when --H is not given
#: 1/H of primal-ms on the 3D models when --H is not given: cubes of side ¼ (on the cube of model 4, 48 of them in
#: Ω₁, each 4 fine cells wide at the default h = 1/16; a 1/16 strip would leave a coarse cell one fine cell wide)
DEFAULT_COARSE_3D_MS = 4
#: the materials of the built-in models when --E-high, --E-low, --nu are not given (the three models share them)
MODEL_DEFAULTS = {
    name: p.default for name, p in inspect.signature(model_1).parameters.items() if name in ("E_high", "E_low", "nu")
}
#: the words --nbasis (and ``[multiscale] nbasis``) takes for primal-ms besides a number: the rigid motions of a
#: coarse cell (its default: 3 in 2D, 6 in 3D) and every local mode (with patches covering Ω₁, the fine space)
NBASIS_WORDS = {"rigid": RIGID_MOTIONS, "all": ALL_MODES}
#: the iteration's defaults (--tol, --max-iterations) and the interface Newton's (--front-window)
_ITERATION = IterationOptions()


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
    "solver": "the linear solver of the primal monolithic reference",
}
#: options of the monolithic reference solve (--reference) rather than of the hybrid method: a method takes one
#: when the monolithic solve of its family does
_REFERENCE_OPTIONS = ("solver",)


def _takes(method: str, name: str) -> bool:
    """Whether ``method`` (a hybrid method) uses the option ``name``, itself or in its monolithic reference."""
    entry = CATALOGUE[method]
    reference = CATALOGUE[f"{entry.family}-monolithic"]
    return name in entry.flat_options() or (name in _REFERENCE_OPTIONS and name in reference.flat_options())


#: the options that only some methods use, and those methods (from the catalogue): giving one to another
#: method is refused, not ignored
_METHOD_OPTIONS: dict[str, tuple[tuple[str, ...], str]] = {
    name: (tuple(m for m in METHODS if _takes(m, name)), hint) for name, hint in _METHOD_OPTION_HINTS.items()
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
    r"^((?P<number>(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?)(Emin|E)?|Emin|E|sqrt-h|h\^\(?[+-]?\d+(\.\d*)?(/\d+)?\)?)$"
)
#: what a positive option is, for its message
_MEANING = {
    "delta": "the primal penalty δ",
    "epsilon": "the mixed penalty ε",
    "E_high": "a Young's modulus",
    "E_low": "a Young's modulus",
}


def _flag(name: str) -> str:
    return "--" + name.replace("_", "-")


def _finite_positive(name: str, value) -> None:
    if value is not None and not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise InputError(f"{_flag(name)} ({_MEANING.get(name, 'a size')}) must be a finite number > 0, got {value!r}")


def _integer(name: str, value, minimum: int) -> None:
    if value is not None and not (isinstance(value, int) and value >= minimum):
        raise InputError(f"{_flag(name)} must be an integer >= {minimum}, got {value!r}")


def _check_nbasis(method: str, nbasis) -> None:
    """An integer >= 1, or for primal-ms one of ``NBASIS_WORDS``."""
    if nbasis is None or (isinstance(nbasis, int) and not isinstance(nbasis, bool) and nbasis >= 1):
        return
    if method == "primal-ms" and nbasis in NBASIS_WORDS:
        return
    words = " or ".join(f'"{w}"' for w in NBASIS_WORDS)
    raise InputError(
        f"--nbasis must be an integer >= 1{f', {words}' if method == 'primal-ms' else ''}, got {nbasis!r}"
        + (f" ({words} apply to primal-ms; mixed-ms takes a number of modes)" if nbasis in NBASIS_WORDS else "")
    )


def _check_alpha(alpha: str) -> None:
    for token in alpha.replace(" ", "").split("*"):
        match = _ALPHA_FACTOR.match(token)
        if match is not None and (match["number"] is None or 0 < float(match["number"]) < math.inf):
            continue
        raise InputError(
            f"cannot read the transmission coefficient --alpha {alpha!r}: give a number > 0 or a "
            "product of numbers, h^p, sqrt-h and E (or Emin), e.g. 1, h^-1/2, 2E*h^-1/2, Emin*h^-1/2"
        )


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


def method_default(method: str, name: str):
    """The default of the option ``name`` of ``method`` in the catalogue: a keyword default of its solve function,
    else a field of its multiscale options dataclass; None when the method has neither."""
    entry = get_method(method)
    defaults = entry.defaults()
    if name in defaults:
        return defaults[name]
    if entry.cem_type is not None and name in (f.name for f in fields(entry.cem_type)):
        return getattr(entry.cem_type(), name)
    return None


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
    H: int | None = None  #: None: ``DEFAULT_COARSE`` (``DEFAULT_COARSE_3D_MS`` for primal-ms on --model 4)
    mesh: Path | None = None
    coarse_groups: bool = False
    alpha: str | None = None
    accel: str | None = None  #: None: the method's default_accel ("newton")
    tol: float = _ITERATION.tol
    max_iterations: int = _ITERATION.max_iterations
    #: the contact Newton's local front resolution (None: InterfaceNewtonOptions' default; 0: off)
    front_window: int | None = None
    delta: float | None = None
    beta: str | None = None
    epsilon: float | None = None
    E_high: float | None = None
    E_low: float | None = None
    nu: float = MODEL_DEFAULTS["nu"]
    E_map: Path | None = None
    layers: int | None = None
    #: local modes per coarse cell: a number, or (primal-ms) "rigid" (the rigid motions) or "all" (every mode)
    nbasis: int | str | None = None
    min_gap: float | None = None
    max_nbasis: int | None = None
    cache_dir: Path | None = None
    reference: bool = False
    #: the linear solver of the primal monolithic reference (None: its default, ``"auto"``)
    solver: str | None = None
    out: Path | None = None  #: None: results/<model N | mesh or case file stem>-<method> (default_out)
    plots: bool = True
    case: Path | None = None  #: the case file the problem came from (``--case``; see ``problem.case``)

    def __post_init__(self) -> None:
        if self.method == "primal-monolithic":
            raise InputError(
                "--method primal-monolithic runs two-body case files only (a case with [pair]); for one body "
                f"choose one of {METHODS}"
            )
        if self.method not in METHODS:
            raise InputError(f"unknown --method {self.method!r}; choose one of {METHODS}")
        get_model(self.model)  # InputError for an unknown model
        if self.accel is None:
            object.__setattr__(self, "accel", default_accel(self.method))
        if self.front_window is not None and self.accel != "newton":
            raise InputError(
                f"--front-window is an option of the interface Newton (--accel newton), not of --accel {self.accel}"
            )
        if self.front_window is not None and (
            isinstance(self.front_window, bool)
            or not isinstance(self.front_window, (int, np.integer))
            or self.front_window < 0
        ):
            raise InputError(f"--front-window must be an integer >= 0 (0: off), got {self.front_window!r}")
        for name, (methods, what) in _METHOD_OPTIONS.items():
            if getattr(self, name) is not None and self.method not in methods:
                raise InputError(f"{_flag(name)} does not apply to --method {self.method} (it is {what})")
        if self.coarse_groups and self.case is not None:
            raise InputError(
                "--coarse-groups does not apply to --case: a case file's surface groups are material "
                "groups; its coarse grid is the Cartesian grid of side 1/H over the bounding box "
                "(mesh.H in the case file)"
            )
        if self.coarse_groups and self.mesh is None:
            raise InputError("--coarse-groups takes the coarse cells from the surface groups of --mesh: give --mesh")
        if self.mesh is not None:
            if self.h is not None:
                raise InputError(
                    "--h sets the size of the built-in mesh; with --mesh the size comes from the file "
                    "(h = sqrt(2 x largest area of a cell on Gamma_C), reported in the summary): "
                    "leave --h out"
                )
            if not Path(self.mesh).is_file():
                raise InputError(
                    f"--mesh {self.mesh} does not exist"
                    if not Path(self.mesh).exists()
                    else f"--mesh {self.mesh} is not a file"
                )
        _integer("h", self.h, 2)
        if self.mesh is None and self.case is None and self.model in MODELS_3D and self.method not in METHODS_3D:
            raise InputError(
                f"--method {self.method} solves plane problems (triangles) only and --model {self.model} is 3D: "
                f"a 3D problem runs with the method {' or '.join(repr(m) for m in METHODS_3D if m in METHODS)}"
            )
        if self.H is None:
            solid_ms = (
                self.mesh is None and self.case is None and self.model in MODELS_3D and self.method.endswith("-ms")
            )
            object.__setattr__(self, "H", DEFAULT_COARSE_3D_MS if solid_ms else DEFAULT_COARSE)
        _integer("H", self.H, 2)
        if self.mesh is None and self.model != MODEL_COMPOSITE_3D and self.n % self.H:  # (a grid of cells)
            raise InputError(
                f"--h {self.n} is not a multiple of --H {self.H}: the coarse grid must be a union of fine cells"
            )
        if self.mesh is None and self.H is not None and self.method.endswith("-ms") and self.n < 2 * self.H:
            raise InputError(
                f"--H {self.H} with --h {self.n}: a coarse cell of the multiscale methods must span at "
                "least 2 fine cells per side (--H at most --h/2; H = h left a mixed-ms local problem "
                "singular)"
            )
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
        _check_nbasis(self.method, self.nbasis)
        _integer("max_nbasis", self.max_nbasis, 1)
        if self.max_nbasis is not None and self.max_nbasis < self.value("nbasis"):
            raise InputError(f"--max-nbasis {self.max_nbasis} must be >= --nbasis {self.value('nbasis')}")
        if self.min_gap is not None and not (math.isfinite(self.min_gap) and self.min_gap >= 0):
            raise InputError(f"--min-gap must be a finite number >= 0, got {self.min_gap!r}")
        if self.solver is not None and self.solver not in LINEAR_SOLVERS:
            raise InputError(f"--solver must be one of {', '.join(LINEAR_SOLVERS)}, got {self.solver!r}")
        if self.alpha is not None:
            _check_alpha(self.alpha)
        if self.beta is not None:
            transmission_coefficient(self.beta, 0.5)
        if self.cache_dir is not None:
            _check_directory("--cache-dir", self.cache_dir)
        out = self.out if self.out is not None else default_out(self.method, self.model, self.mesh, self.case)
        object.__setattr__(self, "out", check_output_target(out))
        for what, path in (
            ("--cache-dir", self.cache_dir),
            ("--case", self.case),
            ("--mesh", self.mesh),
            ("--E-map", self.E_map),
        ):
            check_outside_output(self.out, path, what)

    @classmethod
    def from_namespace(cls, args: argparse.Namespace) -> "RunOptions":
        """From the parsed command line (``build_parser``)."""
        values = {f.name: getattr(args, f.name) for f in fields(cls) if f.name != "plots" and hasattr(args, f.name)}
        return cls(**values, plots=not args.no_plots)

    @property
    def n(self) -> int:
        """1/h of the built-in mesh."""
        if self.h is not None:
            return self.h
        return DEFAULT_H_3D if self.model in MODELS_3D else DEFAULT_H

    def value(self, name: str):
        """The option, or the method's default when it was not given."""
        given = getattr(self, name)
        if given is not None:
            return given
        if name in ("E_high", "E_low"):
            return MODEL_DEFAULTS[name]
        if name in _REFERENCE_OPTIONS:
            return method_default(f"{get_method(self.method).family}-monolithic", name)
        return method_default(self.method, name)

    def method_options(self) -> dict:
        """The chosen method's options given on the command line (its defaults otherwise), for the catalogue."""
        flat = {
            name: getattr(self, name)
            for name in _METHOD_OPTIONS
            if getattr(self, name) is not None and name not in _REFERENCE_OPTIONS
        }
        if "min_gap" in flat:  # --min-gap 0: exactly --nbasis modes (the option's None)
            flat["min_gap"] = flat["min_gap"] or None
        if flat.get("nbasis") in NBASIS_WORDS:  # "rigid", "all": CEMOptions' RIGID_MOTIONS, ALL_MODES
            flat["nbasis"] = NBASIS_WORDS[flat["nbasis"]]
        return flat | {"options": self.iteration_options()}

    def reference_options(self) -> dict:
        """The options of the monolithic reference solve given on the command line (``--solver``)."""
        return {name: getattr(self, name) for name in _REFERENCE_OPTIONS if getattr(self, name) is not None}

    def iteration_options(self) -> IterationOptions:
        return IterationOptions(
            tol=self.tol, max_iterations=self.max_iterations, accel=self.accel, newton=self.newton_options()
        )

    def newton_options(self) -> InterfaceNewtonOptions:
        """The interface Newton's options (the front window of --front-window, else the default)."""
        window = InterfaceNewtonOptions().front_window if self.front_window is None else int(self.front_window)
        return InterfaceNewtonOptions(front_window=window)
