"""Output: ParaView fields (XDMF/HDF5) and the run summary (JSON + markdown table)."""

import json
import os
import platform
from pathlib import Path

import basix.ufl
import dolfinx.io
import numpy as np
from dolfinx import fem
from mpi4py import MPI

from fenics_contact.problem.materials import strain, stress

__all__ = [
    "cell_function_of",
    "cell_markers",
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


def write_summary(directory: str | Path, summary: dict, comm: MPI.Comm = MPI.COMM_WORLD) -> None:
    """DIR/summary.json and DIR/summary.md (a two-column table), written on rank 0."""
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

    (directory / "summary.json").write_text(json.dumps(summary, indent=2, default=plain) + "\n")
    lines = ["| quantity | value |", "|---|---|"]
    for key, value in summary.items():
        if isinstance(value, float):
            value = f"{value:.4g}"
        elif isinstance(value, (list, tuple)) and value and isinstance(value[0], float):
            value = "[" + ", ".join(f"{v:.4g}" for v in value) + "]"
        lines.append(f"| {key} | {value} |")
    (directory / "summary.md").write_text("\n".join(lines) + "\n")
