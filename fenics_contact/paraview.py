"""ParaView datasets of a run: the fields on the mesh and the contact on Γ_C, one time step per load step.

Each series is a VTK collection (``NAME.pvd``) of unstructured grids (``NAME/step_NNN.vtu``), the
time of a step its indentation depth (0 for a single solve): ParaView opens the ``.pvd`` with its
time steps, ``pyvista.read`` (or ``pyvista.PVDReader`` for every step) reads it back.

* ``fields``: the mesh with the displacement ``u`` (point data, P1: the mixed displacement averaged
  at the vertices), the cellwise stress ``sigma`` (xx, yy, zz, xy components), Young's modulus ``E``,
  Poisson's ratio ``nu`` and the ``subdomain`` (1 = Ω₁, 2 = Ω₂).
* ``contact``: the nodes of Γ_C (vertices for the primal methods, Gauss–Lobatto nodes for the mixed
  ones) joined in the profile's order, with the contact ``pressure`` p = −σ_c, the ``gap``
  g − u·ν (> 0 open, < 0 the penalty's penetration), ``active`` (1 where the penalty acts) and the
  contact direction ``normal`` ν.

Data are gathered to rank 0, which writes (collective).
"""

from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np
import pyvista
from dolfinx import fem, plot
from mpi4py import MPI

__all__ = ["Series", "field_grid", "contact_grid"]


class Series:
    """A time series ``DIR/NAME.pvd`` of grids ``DIR/NAME/step_NNN.vtu`` (written on rank 0)."""

    def __init__(self, directory: str | Path, name: str, comm: MPI.Comm = MPI.COMM_WORLD) -> None:
        self.directory, self.name, self.comm = Path(directory), name, comm
        self.steps: list[tuple[float, str]] = []

    @property
    def path(self) -> Path:
        return self.directory / f"{self.name}.pvd"

    def add(self, time: float, grid: pyvista.UnstructuredGrid | None) -> None:
        """Write ``grid`` (rank 0's; None elsewhere) as the next step at ``time`` and rewrite the collection."""
        if self.comm.rank != 0:
            return
        rel = f"{self.name}/step_{len(self.steps):03d}.vtu"
        (self.directory / self.name).mkdir(parents=True, exist_ok=True)
        grid.save(self.directory / rel)
        self.steps.append((float(time), rel))
        rows = "\n".join(f'    <DataSet timestep="{t!r}" part="0" file={quoteattr(f)}/>' for t, f in self.steps)
        self.path.write_text(
            '<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n  <Collection>\n'
            f"{rows}\n  </Collection>\n</VTKFile>\n"
        )


def _gather_grid(V: fem.FunctionSpace, point_values: dict, cell_values: dict) -> pyvista.UnstructuredGrid | None:
    """The owned cells of ``V``'s mesh as one grid on rank 0, its points the dofs of the P1 space V numbered
    globally (a point shared by ranks appears once), with point data at V's dofs and cell data."""
    msh = V.mesh
    tdim = msh.topology.dim
    n_cells = msh.topology.index_map(tdim).size_local
    topology, cell_types, x = plot.vtk_mesh(V)
    per_cell = topology.reshape(-1, topology.size // max(len(cell_types), 1))[:n_cells].copy()
    imap = V.dofmap.index_map
    to_global = imap.local_to_global(np.arange(x.shape[0], dtype=np.int32))
    per_cell[:, 1:] = to_global[per_cell[:, 1:]]
    parts = msh.comm.gather(
        (per_cell, cell_types[:n_cells], to_global, x, point_values, {k: v[:n_cells] for k, v in cell_values.items()}),
        root=0,
    )
    if msh.comm.rank != 0:
        return None
    n_points = imap.size_global
    points = np.zeros((n_points, 3))
    data = {key: np.zeros((n_points, *np.shape(parts[0][4][key])[1:])) for key in point_values}
    for _, _, glob, pts, values, _ in parts:
        points[glob] = pts
        for key in point_values:
            data[key][glob] = values[key]
    grid = pyvista.UnstructuredGrid(
        np.concatenate([p[0].ravel() for p in parts]), np.concatenate([p[1] for p in parts]), points
    )
    for key in point_values:
        grid.point_data[key] = data[key]
    for key in cell_values:
        grid.cell_data[key] = np.concatenate([p[5][key] for p in parts])
    return grid


def _cell_values(fn: fem.Function) -> np.ndarray:
    """A DG0 function's value per local cell, (cells,) or (cells, components)."""
    V = fn.function_space
    msh = V.mesh
    imap = msh.topology.index_map(msh.topology.dim)
    n = imap.size_local + imap.num_ghosts
    bs = V.dofmap.index_map_bs
    dofs = V.dofmap.list[:n, 0]
    values = fn.x.array.reshape(-1, bs)[dofs]
    return values[:, 0] if bs == 1 else values


def field_grid(
    u: fem.Function, stress: np.ndarray, cells: dict[str, fem.Function], nu: fem.Function
) -> pyvista.UnstructuredGrid | None:
    """The mesh of the P1 vector displacement ``u`` with ``u`` as point data, the cellwise plane-strain stress
    ``stress`` (cells, 3: xx, yy, xy) as ``sigma`` in ParaView's symmetric-tensor order (xx, yy, zz, xy, yz, xz;
    σ_zz = ν(σ_xx + σ_yy)), or a 3D stress given in that order (cells, 6), and the DG0 ``cells`` (e.g. E,
    subdomain) as cell data; rank 0's grid."""
    V = u.function_space
    gdim = V.mesh.geometry.dim
    values = np.zeros((u.x.array.size // gdim, 3))
    values[:, :gdim] = u.x.array.reshape(-1, gdim)
    n = stress.shape[0]
    nu_c = _cell_values(nu)[:n]
    sigma = (
        stress
        if stress.shape[1] == 6
        else np.column_stack(
            [stress[:, 0], stress[:, 1], nu_c * (stress[:, 0] + stress[:, 1]), stress[:, 2], np.zeros(n), np.zeros(n)]
        )
    )
    cell_data = {"sigma": sigma} | {name: _cell_values(fn)[:n] for name, fn in cells.items()}
    return _gather_grid(V, {"u": values}, cell_data)


def contact_grid(profile, comm: MPI.Comm = MPI.COMM_WORLD) -> pyvista.UnstructuredGrid | None:
    """The Γ_C nodes of a contact profile (replicated on every rank) joined in its order (on a contact surface,
    3D: the nodes as vertices), with pressure, gap, active and normal as point data; rank 0's grid (None
    elsewhere, and when the profile has no points)."""
    if comm.rank != 0 or profile.points is None:
        return None
    given = np.asarray(profile.points)
    dim = min(given.shape[1], 3)
    points = np.zeros((len(given), 3))
    points[:, :dim] = given[:, :dim]
    n = len(points)
    if dim == 3:
        cells = np.column_stack([np.ones(n, dtype=int), np.arange(n)]).ravel()
        grid = pyvista.UnstructuredGrid(cells, np.full(n, pyvista.CellType.VERTEX, dtype=np.uint8), points)
    else:
        lines = (
            np.column_stack([np.full(n - 1, 2), np.arange(n - 1), np.arange(1, n)]).ravel()
            if n > 1
            else np.zeros(0, dtype=int)
        )
        grid = pyvista.UnstructuredGrid(lines, np.full(max(n - 1, 0), pyvista.CellType.LINE, dtype=np.uint8), points)
    grid.point_data["pressure"] = -np.asarray(profile.sigma_c, dtype=float)
    grid.point_data["gap"] = -np.asarray(profile.u_c, dtype=float)
    grid.point_data["active"] = np.asarray(profile.active, dtype=float)
    if profile.normals is not None:
        normal = np.zeros((n, 3))
        normal[:, :dim] = np.asarray(profile.normals)[:, :dim]
        grid.point_data["normal"] = normal
    return grid
