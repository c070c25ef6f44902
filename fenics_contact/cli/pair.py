"""Two-body case files on the command line: ``fenics-contact run --case TWO_BODIES.toml`` (a case with ``[pair]``).

The run options of a two-body case are few (``PairRunOptions``): the method (``primal-monolithic``, the
penalized Newton on the whole mesh, ``primal``, Algorithm 1 with a strip on each side, or ``primal-ms``,
Algorithm 3: each bulk a CEM-GMsFEM space, ``multiscale.pair``), the penalty δ, the stopping rule and strips
of Algorithms 1 and 3, Algorithm 3's coarse size and CEM options, the output directory and the figures; the
flags ``--method``, ``--out``, ``--no-plots``, ``--delta``, ``--tol``, ``--max-iterations``, ``--accel``,
``--H`` (1/H), ``--layers`` and ``--nbasis`` (the ``[multiscale]`` oversampling layers and modes) override the
case's ``[mesh]``, ``[run]``, ``[primal]`` and ``[multiscale]`` tables, any other flag is refused.  The strip
layers of Algorithms 1 and 3 are the case's ``primal.layers``.  A run solves each load step (warm-started from
the last with ``primal-monolithic`` on one process) and writes ``cli.pair_outputs``' files; under ``mpiexec``
``primal-monolithic`` runs in parallel (``fem.two_body_mpi``), and so does ``primal`` (``hybrid.two_body_mpi``);
``primal-ms`` solves the same serial pair on every rank (``multiscale.pair_replica``: the serial answer, no
speed-up).  With ``[friction]`` each step starts from the friction state the last one committed (the slip of a
step is measured from it), with every method.
"""

import logging
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fenics_contact.cli.options import NBASIS_WORDS
from fenics_contact.cli.pair_outputs import PairWriter, step_row
from fenics_contact.cli.signals import EXIT_NOT_CONVERGED, _fail
from fenics_contact.errors import InputError
from fenics_contact.fem.contact import NewtonOptions
from fenics_contact.fem.two_body import PairState, solve_two_body
from fenics_contact.hybrid.iteration import ACCELERATIONS
from fenics_contact.hybrid.two_body import TwoBodyHybridOptions, solve_two_body_hybrid
from fenics_contact.io import OutputDirectory, provenance, write_summary
from fenics_contact.multiscale.cem import ALL_MODES, CEMOptions
from fenics_contact.multiscale.pair import PairMultiscaleOptions, solve_two_body_ms_hybrid
from fenics_contact.problem.pair_case import PairCase

__all__ = ["PAIR_METHODS", "RUN_KEYS", "PairRunOptions", "check_coarse_size", "pair_run_options", "run_pair"]

log = logging.getLogger("fenics_contact")

#: the methods that solve two deformable bodies
PAIR_METHODS = ("primal-monolithic", "primal", "primal-ms")
#: the keys of a two-body case's run tables (``[primal]`` is read by Algorithms 1 and 3, ``[multiscale]`` by 3)
RUN_KEYS = {
    "run": ("method", "out", "plots", "delta"),
    "primal": ("tol", "max-iterations", "accel", "layers", "alpha-scale"),
    "multiscale": ("layers", "nbasis"),
}
#: the methods that read each table besides [run]
_TABLE_METHODS = {"primal": ("primal", "primal-ms"), "multiscale": ("primal-ms",)}
#: the flags a two-body case takes (argparse dest -> its key)
_FLAGS = {
    "method": "method",
    "out": "out",
    "no_plots": "plots",
    "delta": "delta",
    "tol": "tol",
    "max_iterations": "max-iterations",
    "accel": "accel",
    "layers": "multiscale.layers",
    "nbasis": "multiscale.nbasis",
}
_FRAME = {"command", "case", "set", "verbose", "H"}  #: parser entries that are not run options (--H: mesh.H)


@dataclass(frozen=True, slots=True)
class PairRunOptions:
    """The run of a two-body case: ``method``, penalty ``delta`` (None: ``fem.two_body.two_body_penalty``),
    the ``hybrid`` options of Algorithms 1 and 3, Algorithm 3's ``multiscale`` options (coarse size and CEM
    options; None for the other methods), the output directory and whether to draw the figures."""

    case: Path
    method: str = "primal-monolithic"
    delta: float | None = None
    hybrid: TwoBodyHybridOptions = TwoBodyHybridOptions()
    out: Path | None = None
    plots: bool = True
    multiscale: PairMultiscaleOptions | None = None

    def __post_init__(self) -> None:
        if self.method not in PAIR_METHODS:
            raise InputError(
                f"--method {self.method} cannot solve two deformable bodies (a case with [pair]): the mixed methods "
                f"need an Arnold–Winther contact pair; choose one of {PAIR_METHODS}"
            )
        if (self.method == "primal-ms") != (self.multiscale is not None):
            raise InputError("PairRunOptions: multiscale options (PairMultiscaleOptions) go with primal-ms, and only")
        if self.delta is not None and not (np.isfinite(self.delta) and self.delta > 0):
            raise InputError(f"--delta must be a finite number > 0, got {self.delta!r}")
        out = Path("results") / f"{Path(self.case).stem}-{self.method}" if self.out is None else Path(self.out)
        object.__setattr__(self, "out", out)

    def echo(self) -> dict:
        out = {"method": self.method, "delta": self.delta, "out": str(self.out), "plots": self.plots}
        if self.method != "primal-monolithic":
            h = self.hybrid
            out |= {
                "tol": h.tol,
                "max-iterations": h.max_iterations,
                "accel": h.accel,
                "layers": h.layers,
                "alpha-scale": h.alpha_scale,
            }
        if self.multiscale is not None:
            cem = self.multiscale.cem
            nbasis = "all" if cem.nbasis is ALL_MODES else cem.nbasis
            out |= {"coarse-size": self.multiscale.H, "multiscale": {"layers": cem.layers, "nbasis": nbasis}}
        return out


def _typed(case: PairCase, key: str, value, kind: type):
    ok = (
        isinstance(value, bool)
        if kind is bool
        else isinstance(value, str)
        if kind in (str, Path)
        else not isinstance(value, bool) and isinstance(value, int if kind is int else (int, float))
    )
    if not ok:
        what = {bool: "true or false", str: "a string", Path: "a directory name", int: "an integer"}.get(
            kind, "a number"
        )
        raise InputError(f"case {case.path}: {key} must be {what}, got {value!r}")
    return Path(value) if kind is Path else float(value) if kind is float else value


_KINDS = {
    "method": str,
    "out": Path,
    "plots": bool,
    "delta": float,
    "tol": float,
    "max-iterations": int,
    "accel": str,
    "layers": int,
    "alpha-scale": float,
    "multiscale.layers": int,
    "multiscale.nbasis": int,
}


def pair_run_options(case: PairCase, given: Mapping[str, object] = {}) -> PairRunOptions:
    """The run options from the case's ``[run]``, ``[primal]`` and ``[multiscale]`` tables, then the flags ``given``
    (dest -> value)."""
    values = {}
    for table, keys in RUN_KEYS.items():
        for key, value in case.run[table].items():
            if key not in keys:
                home = next((t for t, k in RUN_KEYS.items() if key in k), None)
                hint = f" ({key} belongs in [{home}])" if home else ""
                raise InputError(
                    f"case {case.path}: unknown key '{table}.{key}' in a two-body case{hint}; the keys of [{table}] "
                    f"are {list(keys)}"
                )
            name = f"multiscale.{key}" if table == "multiscale" else key
            if name == "multiscale.nbasis" and isinstance(value, str):
                if value not in NBASIS_WORDS:
                    raise InputError(
                        f'case {case.path}: multiscale.nbasis must be an integer >= 1, "rigid" or "all", got {value!r}'
                    )
                values[name] = NBASIS_WORDS[value]
                continue
            values[name] = _typed(case, f"{table}.{key}", value, _KINDS[name])
    refused = sorted(f"--{d.replace('_', '-')}" for d in given if d not in _FLAGS and d not in _FRAME)
    if refused:
        raise InputError(
            f"{refused[0]} does not apply to a two-body case; its flags are "
            + ", ".join(f"--{d.replace('_', '-')}" for d in (*_FLAGS, "H"))
        )
    for dest, key in _FLAGS.items():
        if dest in given:
            values[key] = (not given[dest]) if dest == "no_plots" else given[dest]
    if values.get("multiscale.nbasis") in NBASIS_WORDS:  # (--nbasis rigid | all)
        values["multiscale.nbasis"] = NBASIS_WORDS[values["multiscale.nbasis"]]
    method = values.get("method", "primal-monolithic")
    hybrid = {k: values[k] for k in RUN_KEYS["primal"] if k in values}
    cem = {k: values[f"multiscale.{k}"] for k in RUN_KEYS["multiscale"] if f"multiscale.{k}" in values}
    for table, given_keys in (("primal", hybrid), ("multiscale", cem)):
        if given_keys and method not in _TABLE_METHODS[table]:
            users = " and ".join(_TABLE_METHODS[table])
            raise InputError(
                f"{', '.join(sorted(given_keys))}: options of --method {users}, not of --method {method} (in a case "
                f"file they belong in [{table}], read only by {users})"
            )
    if hybrid.get("accel") is not None and hybrid["accel"] not in ACCELERATIONS:
        raise InputError(f"--accel must be one of {list(ACCELERATIONS)}, got {hybrid['accel']!r}")
    options = TwoBodyHybridOptions(**{k.replace("-", "_"): v for k, v in hybrid.items()})
    multiscale = _multiscale_options(case, cem) if method == "primal-ms" else None
    return PairRunOptions(
        case.path,
        method,
        values.get("delta"),
        options,
        values.get("out"),
        values.get("plots", True),
        multiscale,
    )


def _multiscale_options(case: PairCase, cem: Mapping[str, int]) -> PairMultiscaleOptions:
    """Algorithm 3's options of a two-body case: InputError when it cannot run the case (no coarse size)."""
    if case.coarse_size is None:
        raise InputError(
            f"case {case.path}: --method primal-ms needs the coarse size of both bulks: give mesh.coarse-size "
            "(a length in mesh units) or mesh.H / --H (1/H)"
        )
    return PairMultiscaleOptions(case.coarse_size, CEMOptions(**cem))


def check_coarse_size(problem, H: float) -> None:
    """InputError unless the coarse squares of side ``H`` divide each body: at least one fine cell across and at
    least two coarse cells along a body's longer side (collective)."""
    msh, comm = problem.mesh, problem.mesh.comm
    tdim = msh.topology.dim
    n_cells = msh.topology.index_map(tdim).size_local
    h = float(np.median(np.concatenate(comm.allgather(msh.h(tdim, np.arange(n_cells, dtype=np.int32))))))
    if H < h:
        raise InputError(
            f"the coarse size H = {H:g} (mesh.coarse-size, or 1/--H) is smaller than the fine cells (median "
            f"diameter {h:.3g}): a coarse cell of primal-ms spans fine cells; give a coarse size of several of them"
        )
    x = msh.geometry.x
    for k in (0, 1):
        nodes = np.unique(msh.geometry.dofmaps[0][problem.body_cells(k)])
        low, high = np.min(x[nodes, :tdim], axis=0, initial=np.inf), np.max(x[nodes, :tdim], axis=0, initial=-np.inf)
        comm.Allreduce(MPI.IN_PLACE, low, op=MPI.MIN)
        comm.Allreduce(MPI.IN_PLACE, high, op=MPI.MAX)
        side = float(np.max(high - low))
        if H >= side / 2:
            raise InputError(
                f"the coarse size H = {H:g} (mesh.coarse-size, or 1/--H) does not divide body {k + 1} (its longer "
                f"side {side:.3g}): primal-ms needs at least two coarse cells along it; give H below half of it"
            )


def _solve(options: PairRunOptions, problem, state: PairState | None):
    """One solve of the run's method from the previous load step's ``state``: the monolithic Newton's warm start
    and, with friction, the anchors the step's slip is measured from (Algorithm 1: also its interface data)."""
    if options.method == "primal-monolithic":
        return solve_two_body(problem, delta=options.delta, newton=NewtonOptions(), state=state)
    if problem.friction is None:
        state = None  # (frictionless: each step from the unloaded pair, as the paper's iteration)
    if options.method == "primal-ms":
        return solve_two_body_ms_hybrid(
            problem, options.multiscale, delta=options.delta, options=options.hybrid, state=state
        )
    return solve_two_body_hybrid(problem, delta=options.delta, options=options.hybrid, state=state)


def _converged(result) -> bool:
    return bool(getattr(result, "converged", True))


def run_pair(options: PairRunOptions, comm: MPI.Comm, case: PairCase) -> int:
    """Solve the case (each load step), write into ``options.out``; 0 converged, 3 not converged."""
    output = OutputDirectory(options.out, comm)
    with output:
        t0 = time.perf_counter()
        built = case.build_mesh(comm)
        steps = case.load.steps if case.load else (None,)
        t_mesh = time.perf_counter() - t0
        log.info("case %s (%s), method %s", case.path.name, case.description_or_name, options.method)
        writer = PairWriter(output.path, comm, options.plots, f"case {case.path.name}, {options.method}")
        rows, result, state = [], None, None
        quantity = case.load.quantity if case.load else None
        for k, displacement in enumerate(steps):
            problem = case.problem(built, step=None if displacement is None else k)
            if options.multiscale is not None and k == 0:
                check_coarse_size(problem, options.multiscale.H)
            result = _solve(options, problem, state)
            state = result.state  # (under MPI only its friction anchors are used: a warm start is serial)
            row = step_row(result, options.method)
            if displacement is not None:
                row = {"step": k + 1, quantity: list(displacement)} | row
                log.info(
                    "step %d, %s %s: contact force %.6g on the slave side, balance %.2e",
                    k + 1,
                    quantity,
                    list(displacement),
                    result.slave.force,
                    result.force_balance(),
                )
            rows.append(row)
            writer.add_step(k + 1 if displacement is not None else 0.0, problem, result)
        converged = all(r["converged"] for r in rows)
        summary = {
            "method": options.method,
            "mesh": str(case.mesh_file),
            "converged": converged,
            **rows[-1],
            "time_mesh_s": t_mesh,
            "mpi_ranks": comm.size,
            "provenance": provenance(),
            "load_steps": {case.load.kind: case.load.group, "steps": rows} if case.load else None,
            "dissipation": float(sum(r["friction"]["dissipation"] for r in rows)) if case.friction else None,
            "case": case.to_dict() | {"run": options.echo()},
        }
        if options.multiscale is not None:  # Algorithm 3's coarse space in each bulk
            cem = options.multiscale.cem
            summary |= {"coarse_size": options.multiscale.H, "layers": cem.layers, "nbasis": cem.nbasis or "all"}
        summary.pop("step", None)
        summary.pop(quantity, None)
        writer.finish(problem, result, summary)
        write_summary(output.path, summary, comm)
        output.commit()
    if not converged:
        bad = [str(r.get("step", "")) for r in rows if not r["converged"]]
        _fail(
            f"not converged: the interface iteration stopped above --tol {options.hybrid.tol:g} "
            f"(step(s) {', '.join(bad)}); "
            f'results in {options.out} with "converged": false',
            comm,
        )
        return EXIT_NOT_CONVERGED
    log.info(
        "converged; contact force %.6g (slave), %.6g (master), balance %.2e; summary in %s",
        result.slave.force,
        result.master.force,
        result.force_balance(),
        options.out / "summary.json",
    )
    return 0
