"""Output: ParaView fields (XDMF/HDF5), the run summary (JSON + markdown table), and the run directory.

A run's directory is written whole or not at all (``OutputDirectory``): every file goes
into a hidden staging directory beside the target, which replaces the target only when
the run has finished; an interrupted or failed run leaves the target as it was.
"""

import contextlib
import json
import os
import platform
import re
import resource
import shutil
import signal
import socket
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import basix.ufl
import dolfinx.io
import dolfinx.jit
import numpy as np
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from fenics_contact import __version__
from fenics_contact.errors import InputError, OutputError
from fenics_contact.problem.materials import strain, stress

__all__ = [
    "peak_rss_bytes",
    "process_alive",
    "provenance",
    "OutputDirectory",
    "cell_function_of",
    "cell_markers",
    "check_output_target",
    "check_jit_cache",
    "check_outside_output",
    "machine_description",
    "stress_field",
    "write_fields",
    "write_summary",
    "write_vtx",
]


def cell_markers(cell_tags, msh) -> fem.Function:
    """DG0 function with the subdomain tag (1 = Ω₁, 2 = Ω₂) of every cell."""
    V = fem.functionspace(msh, ("DG", 0))
    marker = fem.Function(V, name="subdomain")
    marker.x.array[cell_tags.indices] = cell_tags.values
    marker.x.scatter_forward()
    return marker


def write_fields(path: str | Path, msh, functions: list[fem.Function]) -> Path:
    """Write P1 and DG0 functions to one XDMF file (open it in ParaView)."""
    path = Path(path).with_suffix(".xdmf")
    with dolfinx.io.XDMFFile(msh.comm, str(path), "w") as xdmf:
        xdmf.write_mesh(msh)
        for fn in functions:
            xdmf.write_function(fn)
    return path


def stress_field(u: fem.Function, lmbda, mu, name: str = "sigma") -> fem.Function:
    """σ(u) as a DG0 tensor function (cellwise constant for P1 displacements)."""
    msh = u.function_space.mesh
    gdim = msh.geometry.dim
    S = fem.functionspace(msh, basix.ufl.element("DG", msh.basix_cell(), 0, shape=(gdim, gdim)))
    sigma = fem.Function(S, name=name)
    expr = fem.Expression(stress(strain(u), lmbda, mu), S.element.interpolation_points)
    sigma.interpolate(expr)
    return sigma


def cell_function_of(fn: fem.Function, *, name: str) -> fem.Function:
    """The values of ``fn`` at the cell midpoints as a DG0 function (for cellwise output of DG fields)."""
    msh = fn.function_space.mesh
    shape = fn.function_space.value_shape
    V0 = fem.functionspace(msh, basix.ufl.element("DG", msh.basix_cell(), 0, shape=tuple(shape)))
    out = fem.Function(V0, name=name)
    out.interpolate(fn)
    return out


def write_vtx(path: str | Path, fn: fem.Function) -> Path:
    """Write one function of any degree (e.g. the DG P3 Arnold–Winther stress) as ADIOS2/VTX for ParaView."""
    path = Path(path)
    with dolfinx.io.VTXWriter(fn.function_space.mesh.comm, str(path), [fn], engine="BP4") as writer:
        writer.write(0.0)
    return path


def peak_rss_bytes() -> int:
    """The high-water mark of this process's resident set, in bytes (Linux reports ``ru_maxrss`` in KiB).

    Summaries and benchmarks report it as GB = 10⁹ bytes (or MB = 10⁶ bytes)."""
    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * 1024


def machine_description() -> str:
    """One line describing this machine (for benchmark tables): CPU, cores, OS, Python, threads, ranks."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next((line.split(":", 1)[1].strip() for line in f if line.startswith("model name")), cpu)
    except OSError:
        pass
    return (
        f"{cpu}, {os.cpu_count()} logical cores, {platform.system()} {platform.release()}, "
        f"Python {platform.python_version()}, OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS', 'unset')}, "
        f"MPI ranks {MPI.COMM_WORLD.size}"
    )


def provenance() -> dict:
    """What made a result: the package, DOLFINx, PETSc and Python versions, the command line, the UTC time and
    the machine, and the peak memory of this process so far (rank 0's, GB = 10⁹ bytes)."""
    return {
        "fenics_contact": __version__,
        "dolfinx": dolfinx.__version__,
        "petsc": ".".join(map(str, PETSc.Sys.getVersion())),
        "python": platform.python_version(),
        "command": " ".join([Path(sys.argv[0]).name, *sys.argv[1:]]),
        "utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "machine": machine_description(),
        "peak_memory_gb": round(peak_rss_bytes() / 1e9, 3),
    }


def _cell(value) -> str:
    """A summary value for a table cell: numbers to 4 significant digits, short lists inline."""
    if isinstance(value, bool) or value is None:
        return str(value)
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_cell(v) for v in value) + "]"
    return str(value)


def _markdown(summary: dict, title: str, level: int = 1) -> list[str]:
    """A table of the plain entries of ``summary``, then a section per nested table (a list of records as one
    table with a row per record)."""
    plain = {k: v for k, v in summary.items() if not isinstance(v, dict) and not _records(v)}
    lines = [f"{'#' * level} {title}", ""]
    if plain:
        lines += ["| quantity | value |", "|---|---|"] + [f"| {k} | {_cell(v)} |" for k, v in plain.items()] + [""]
    for key, value in summary.items():
        if isinstance(value, dict):
            lines += _markdown(value, key, level + 1)
        elif _records(value):
            columns = list(dict.fromkeys(k for row in value for k, v in row.items() if not isinstance(v, dict)))
            lines += [f"{'#' * (level + 1)} {key}", "", "| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
            lines += ["| " + " | ".join(_cell(row.get(c)) for c in columns) + " |" for row in value] + [""]
    return lines


def _records(value) -> bool:
    return isinstance(value, list) and bool(value) and all(isinstance(v, dict) for v in value)


def _finite(value):
    """``value`` with every float that is inf or NaN (nested in dicts, lists and tuples) replaced by None."""
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    if isinstance(value, (float, np.floating)) and not np.isfinite(value):
        return None
    return value


def write_summary(directory: str | Path, summary: dict, comm: MPI.Comm = MPI.COMM_WORLD) -> None:
    """DIR/summary.json and DIR/summary.md (tables: the run's quantities, then one per nested result), rank 0."""
    if comm.rank != 0:
        return
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)

    def plain(value):
        if isinstance(value, (np.floating, np.integer)):
            return value.item()
        if isinstance(value, np.ndarray):
            return value.tolist()
        raise TypeError(f"cannot serialize {type(value)}")

    summary = _finite(summary)  # (JSON has no inf or NaN: a relative error of a vanishing reference is null)
    (directory / "summary.json").write_text(json.dumps(summary, indent=2, default=plain, allow_nan=False) + "\n")
    title = f"fenics-contact run: {summary.get('method', '')}".strip()
    (directory / "summary.md").write_text("\n".join(_markdown(summary, title)) + "\n")


# ---------------------------------------------------------------------------------------------
# the run directory: whole or absent
# ---------------------------------------------------------------------------------------------
#: marker file in every run directory, listing what the run wrote: a directory holding it and nothing else may be
#: replaced
RUN_MARKER = ".fenics-contact-run"
#: the marker's first line (then one line per entry the run wrote)
RUN_MARKER_HEADER = "written by fenics-contact: the next run replaces it whole; the entries it wrote:"
#: staging / previous-contents directories beside the target: .fenics-contact-<pid>@<host>-<random>.{partial,old}
_STAGING = re.compile(r"^\.fenics-contact-(?P<pid>\d+)@(?P<host>.+)-[^-]+\.(partial|old)$")
_STALE_AGE_S = 24 * 3600.0


def _is_run_directory(path: Path) -> bool:
    """True if ``path`` is empty or holds exactly what a fenics-contact run wrote there (so it may be replaced):
    its marker lists the entries the run wrote, and nothing else is there (a file the user added, a copied
    summary, a case file or a cache directory kept inside it make it the user's; the staging directories of
    runs into it are not counted)."""
    entries = {entry.name for entry in path.iterdir() if not _STAGING.match(entry.name)}
    if not entries:
        return True
    try:
        lines = (path / RUN_MARKER).read_text().splitlines()
    except (OSError, UnicodeDecodeError):
        return False
    if not lines or lines[0] != RUN_MARKER_HEADER:
        return False
    return entries <= {RUN_MARKER, *lines[1:]}


def check_jit_cache() -> Path:
    """The directory where DOLFINx keeps the compiled forms (``$XDG_CACHE_HOME/fenics``, or the ``cache_dir`` of
    its JIT options), created if need be; InputError when it cannot be created or written, before a form is
    compiled (FFCx would fail with a traceback there)."""
    cache = Path(dolfinx.jit.get_options()["cache_dir"])
    try:
        cache.mkdir(parents=True, exist_ok=True)
        ok = os.access(cache, os.W_OK | os.X_OK)
        reason = "it is not writable"
    except OSError as err:
        ok, reason = False, err.strerror or str(err)
    if not ok:
        raise InputError(
            f"the cache of compiled forms {cache} cannot be used: {reason}; point XDG_CACHE_HOME (or cache_dir "
            "in a dolfinx_jit_options.json) to a writable directory"
        )
    return cache


def check_outside_output(target: str | Path, path: str | Path | None, what: str) -> None:
    """InputError when ``path`` (an input file or the cache directory, named ``what``) lies inside the output
    directory ``target``: the run replaces ``target`` whole and would delete it."""
    if path is None:
        return
    out, inner = Path(target).resolve(), Path(path).resolve()
    if inner == out or out in inner.parents:
        raise InputError(
            f"{what} {path} lies inside --out {target}, which the run replaces whole: keep it outside "
            "the output directory (or choose another --out)"
        )


def check_output_target(target: str | Path) -> Path:
    """The output directory ``target`` as a Path; InputError unless a run can be written there and replace it.

    Refused: an empty name, the current directory or one containing it, an existing file, a
    directory that is not an earlier run's (it would be replaced as a whole), a path below a file,
    names longer than the file system allows, a parent that is not writable.
    """
    if not str(target).strip():
        raise InputError("--out must name a directory (got an empty string)")
    target = Path(target)
    absolute = Path(os.path.abspath(target))
    existing = _nearest_existing(absolute)
    name_max = os.pathconf(existing if existing.is_dir() else existing.parent, "PC_NAME_MAX")
    long_names = [part for part in absolute.parts if len(os.fsencode(part)) > name_max]
    if long_names:
        raise InputError(
            f"--out: the name {long_names[0][:40]}… is longer than the {name_max} bytes the file system allows"
        )
    if len(os.fsencode(str(absolute))) + 64 > os.pathconf(
        existing if existing.is_dir() else existing.parent, "PC_PATH_MAX"
    ):
        raise InputError(f"--out: the path {str(absolute)[:60]}… is too long for the file system")
    resolved = target.resolve()
    cwd = Path.cwd().resolve()
    if resolved == cwd or resolved in cwd.parents:
        raise InputError(
            f"--out {target} is the current directory or contains it: the run replaces --out as a "
            "whole, so name a directory of its own (e.g. results/run1)"
        )
    existing = _nearest_existing(resolved)
    if existing != resolved and not existing.is_dir():
        raise InputError(f"--out {target} lies below {existing}, which is a file, not a directory")
    if resolved.exists():
        if not resolved.is_dir():
            raise InputError(f"--out {target} exists and is a file, not a directory")
        if not os.access(resolved, os.R_OK | os.X_OK):
            raise InputError(f"--out {target} cannot be read")
        if not _is_run_directory(resolved):
            raise InputError(
                f"--out {target} holds files that are not the output of a fenics-contact run; the run "
                "would replace the directory as a whole. Choose another directory or empty it."
            )
    home = resolved if resolved.exists() else existing  # (an existing --out is filled in place)
    if not os.access(home, os.W_OK | os.X_OK):
        raise InputError(f"--out {target}: {home} is not writable")
    return target


def _nearest_existing(path: Path) -> Path:
    """``path`` or its nearest ancestor that exists."""
    while True:
        try:
            if path.exists() or path == path.parent:
                return path
        except OSError:  # e.g. a name too long to look up
            pass
        path = path.parent


def process_alive(pid: int) -> bool:
    """True if the process ``pid`` exists (on this host)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _remove_stale_staging(parent: Path) -> None:
    """Remove staging / previous-contents directories of runs that died (kill -9) in ``parent``."""
    host = socket.gethostname()
    now = time.time()
    for path in parent.glob(".fenics-contact-*"):
        match = _STAGING.match(path.name)
        if match is None or not path.is_dir():
            continue
        try:
            stale = (
                not process_alive(int(match["pid"]))
                if match["host"] == host
                else now - path.stat().st_mtime > _STALE_AGE_S
            )
        except OSError:
            continue
        if stale:
            shutil.rmtree(path, ignore_errors=True)


@contextlib.contextmanager
def _signals_blocked() -> Iterator[None]:
    """SIGINT and SIGTERM held back (delivered at the end) for a few file-system operations."""
    signals = {signal.SIGINT, signal.SIGTERM}
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, signals)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


class OutputDirectory:
    """A run directory written whole or not at all (collective over ``comm``).

    ``path`` is a hidden staging directory (created on rank 0, the same path on every rank): inside
    ``target`` when that is an existing directory (empty or an earlier run's: it is filled in place, never
    removed or renamed, so that a mount point or a directory owned by someone else serves), beside it
    otherwise. Write every file there. ``commit()`` puts its entries in the place of ``target``'s (whose
    previous contents are removed only then: a reused ``--out`` ends holding exactly one run); leaving the
    ``with`` block without ``commit()`` (an error, an interrupt) removes it and leaves ``target`` as it was.
    Staging directories of runs that were killed are removed when the next run starts beside or in them.
    """

    #: the exit code of a run whose ranks a failed write ends (MPI_Abort; the command line's EXIT_WRITE)
    ABORT_CODE = 5

    def __init__(self, target: str | Path, comm: MPI.Comm = MPI.COMM_WORLD) -> None:
        self.target = Path(target)
        self.comm = comm
        self.committed = False
        result = None
        if comm.rank == 0:
            try:
                check_output_target(self.target)
                resolved = self.target.resolve()
                home = resolved if resolved.is_dir() else resolved.parent
                home.mkdir(parents=True, exist_ok=True)
                _remove_stale_staging(home)
                prefix = f".fenics-contact-{os.getpid()}@{socket.gethostname()}-"
                result = Path(tempfile.mkdtemp(prefix=prefix, suffix=".partial", dir=home))
                umask = os.umask(0o022)
                os.umask(umask)
                result.chmod(0o777 & ~umask)  # mkdtemp makes it private; the results are an ordinary directory
            except InputError as err:
                result = err
            except OSError as err:
                result = InputError(
                    f"--out {self.target}: cannot create a directory in "
                    f"{self.target.resolve().parent}: {err.strerror or err}"
                )
        result = comm.bcast(result, root=0)
        if isinstance(result, InputError):
            raise result
        self.path: Path = result
        self.in_place = self.path.parent == self.target.resolve()

    def __enter__(self) -> "OutputDirectory":
        return self

    def __exit__(self, *exc) -> None:
        if not self.committed:
            self.discard()

    def check_space(self, need: float, what: str = "the results") -> None:
        """OutputError (on every rank) when the file system of ``path`` has less than ``need`` bytes free."""
        free = None
        if self.comm.rank == 0:
            try:
                stat = os.statvfs(self.path)
                free = stat.f_bavail * stat.f_frsize
            except OSError:
                pass
        free = self.comm.bcast(free, root=0)
        if free is not None and free < need:
            raise OutputError(
                f"--out {self.target}: {what} need about {_megabytes(need)} and its file system has "
                f"{_megabytes(free)} free: free some space or choose another --out"
            )

    @contextlib.contextmanager
    def writing(self) -> Iterator[None]:
        """Write the results: a failed write (a full disk, a removed directory) is an OutputError."""
        try:
            yield
        except OSError as err:
            if isinstance(err, OutputError):
                raise
            where = f" ({Path(err.filename).name})" if err.filename else ""
            error = OutputError(f"--out {self.target}: could not write the results{where}: {err.strerror or err}")
            if self.comm.size > 1:  # the other ranks may wait in a collective write: only ending them all is sure
                print(f"error: {error}", file=sys.stderr, flush=True)
                self.comm.Abort(self.ABORT_CODE)
            raise error from None

    def commit(self) -> None:
        """Put the staging directory's entries in ``target`` (collective; SIGINT/SIGTERM held back until done)."""
        error = None
        with _signals_blocked():
            self.comm.Barrier()  # every rank has closed its files
            if self.comm.rank == 0:
                try:
                    names = sorted(entry.name for entry in self.path.iterdir())
                    (self.path / RUN_MARKER).write_text("\n".join([RUN_MARKER_HEADER, *names]) + "\n")
                    self._fill() if self.in_place else self._swap()
                except OSError as err:
                    error = f"--out {self.target}: could not move the results into place: {err}"
            error = self.comm.bcast(error, root=0)
            self.committed = self.comm.bcast(self.committed, root=0)
        if error is not None:
            raise OutputError(error)

    def _swap(self) -> None:
        """``target`` does not exist: the staging directory becomes it."""
        os.rename(self.path, self.target.resolve())
        self.committed = True

    def _fill(self) -> None:
        """``target`` exists (the staging directory is inside it): its entries move to a directory of the previous
        contents, the staging directory's into ``target``; on a failure everything moves back."""
        target = self.target.resolve()
        old = self.path.with_suffix(".old")
        old.mkdir()
        moved_out, moved_in = [], []
        try:
            for entry in sorted(target.iterdir()):
                if not _STAGING.match(entry.name):
                    os.rename(entry, old / entry.name)
                    moved_out.append(entry.name)
            for entry in sorted(self.path.iterdir()):
                os.rename(entry, target / entry.name)
                moved_in.append(entry.name)
        except OSError:
            for name in moved_in:
                os.rename(target / name, self.path / name)
            for name in moved_out:
                os.rename(old / name, target / name)
            old.rmdir()
            raise
        self.committed = True
        self.path.rmdir()
        shutil.rmtree(old, ignore_errors=True)

    def discard(self) -> None:
        """Remove the staging directory (every rank: under MPI an interrupted rank may end the run while rank 0
        waits in a collective operation); ``target`` is untouched."""
        shutil.rmtree(self.path, ignore_errors=True)


def _megabytes(n: float) -> str:
    return f"{n / 1e6:.3g} MB"
