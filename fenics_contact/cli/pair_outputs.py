"""What a two-body run writes: the summary entries of a solve, the ParaView series and the figures.

* ``fields.pvd``: both bodies' mesh with the displacement ``u``, the cellwise stress ``sigma``, ``E``, ``nu`` and
  ``body`` (1, 2: the case's first and second body), one time step per load step (the step number; 0 without
  load steps);
* ``contact.pvd``: the nodes of both contact surfaces with ``pressure`` (−σ_c), ``gap``, ``active``, ``normal``
  and ``side`` (1 slave, 2 master);
* ``pair.png`` (2D): the deformed bodies (magnified, coloured by |u|, the contact surfaces drawn) beside the contact
  pressure along each surface; ``E.png`` (2D); ``force_displacement.png`` with load steps: the normal contact force
  on each side (with friction also the tangential force on the slave side) against the stepped support's
  displacement or traction.
"""

from pathlib import Path

import numpy as np
import pyvista
from dolfinx import plot
from mpi4py import MPI

from fenics_contact.cli.outputs import _cell_array, _friction_summary
from fenics_contact.io import cell_markers, stress_field
from fenics_contact.paraview import Series, contact_grid, field_grid
from fenics_contact.plots import _save, plot_cell_field, plt

__all__ = ["PairWriter", "step_row", "plot_pair", "plot_force_displacement"]


def _interval(profile) -> list[float] | None:
    span = profile.active_interval()
    return [float(span[0]), float(span[1])] if span is not None else None


def step_row(result, method: str) -> dict:
    """The summary entries of one two-body solve: the forces on each side and their balance, the pressures, the
    contact zones (along each surface's major coordinate), the solver's counts; with friction ``friction``: the
    slave side's normal and tangential force, stick and slip nodes and zones, the step's dissipation."""
    slave, master = result.slave, result.master
    row = {
        "converged": bool(getattr(result, "converged", True)),
        "delta": float(result.delta),
        # the resultant contact force on each body (N per unit thickness in N, mm): equal and opposite
        "force_slave": [float(v) for v in result.forces[0]],
        "force_master": [float(v) for v in result.forces[1]],
        "force_balance": result.force_balance(),
        "normal_force_slave": slave.force,
        "normal_force_master": master.force,
        "max_contact_pressure_slave": slave.max_pressure,
        "max_contact_pressure_master": master.max_pressure,
        "contact_zone_slave": _interval(slave),
        "contact_zone_master": _interval(master),
        "penetration": slave.penetration,
        "time_s": float(result.time_s),
    }
    if result.friction is not None:  # the slave side's tangential summary (the master's is its opposite)
        row["friction"] = _friction_summary(result.friction, result.dissipation)
    if method == "primal-monolithic":
        row |= {"newton_steps": result.newton.steps, "dofs": int(result.dofs)}
    else:
        row |= {
            "iterations": result.iterations,
            "transmission_residual": result.transmission_residual,
            "transmission_floor": result.floor,
            "status": result.status,
            "newton_steps_total": int(sum(h.steps for h in result.newton)),
            # (the owned strip cells of each rank, summed)
            "strip_cells": int(result.u.function_space.mesh.comm.allreduce(int(result.strip.size))),
        }
    return row


def _pair_contact_grid(result, comm: MPI.Comm) -> pyvista.UnstructuredGrid | None:
    """Both surfaces' contact grids in one, with ``side`` 1 (slave) and 2 (master)."""
    grids = []
    for side, profile in ((1, result.slave), (2, result.master)):
        grid = contact_grid(profile, comm)
        if grid is not None:
            grid.point_data["side"] = np.full(grid.n_points, float(side))
            grids.append(grid)
    if not grids:
        return None
    return grids[0].merge(grids[1:], merge_points=False) if len(grids) > 1 else grids[0]


class PairWriter:
    """The series ``fields`` and ``contact`` of a two-body run (a step per load step) and its figures."""

    def __init__(self, directory: Path, comm: MPI.Comm, plots: bool, title: str) -> None:
        self.directory, self.comm, self.plots, self.title = Path(directory), comm, plots, title
        self.fields, self.contact = Series(directory, "fields", comm), Series(directory, "contact", comm)

    def add_step(self, time: float, problem, result) -> None:
        fields = problem.fields
        s = _cell_array(stress_field(result.u, fields.lmbda, fields.mu))
        if problem.dim == 3:  # (xx, yy, zz, xy, yz, xz) of the 3 × 3 stress, row by row
            stress = s[:, [0, 4, 8, 1, 5, 2]]
        else:
            stress = np.column_stack([s[:, 0], s[:, 3], s[:, 1]])
        markers = cell_markers(problem.cell_tags, problem.mesh)
        markers.name = "body"
        self.fields.add(time, field_grid(result.u, stress, {"E": fields.E, "body": markers}, fields.nu))
        self.contact.add(time, _pair_contact_grid(result, self.comm))

    def finish(self, problem, result, summary: dict) -> None:
        if not self.plots:
            return
        if problem.dim == 2:  # (in 3D the fields and the contact pressure are for ParaView)
            plot_cell_field(
                problem.fields.E, self.directory / "E.png", title=f"Young's modulus, {self.title}", log=True
            )
            plot_pair(result, problem, self.directory / "pair.png", title=self.title)
        if summary.get("load_steps") and self.comm.rank == 0:
            plot_force_displacement(summary["load_steps"], self.directory / "force_displacement.png", self.title)


def _along(points: np.ndarray) -> tuple[np.ndarray, str]:
    """The coordinate a surface spans most (x or y) and its name."""
    k = int(np.argmax(np.ptp(points[:, :2], axis=0)))
    return points[:, k], "xy"[k]


def plot_pair(result, problem, path: str | Path, *, title: str = "", scale: float | None = None) -> Path | None:
    """The deformed bodies (displacements magnified by ``scale``, default 10 % of the extent over max |u|),
    coloured by |u| with both contact surfaces drawn, beside the contact pressure −σ_c along each surface.
    Collective: the mesh is gathered to rank 0, which draws (None elsewhere)."""
    u = result.u
    V = u.function_space
    topology, _, x = plot.vtk_mesh(V)
    n_cells = V.mesh.topology.index_map(V.mesh.topology.dim).size_local
    body = np.zeros(n_cells)
    for k, b in enumerate(problem.bodies):
        cells = problem.cell_tags.find(b.cells)
        body[cells[cells < n_cells]] = k
    parts = V.mesh.comm.gather(
        (
            topology.reshape(-1, 4)[:n_cells, 1:],
            x,
            u.x.array.reshape(-1, V.dofmap.index_map_bs)[: x.shape[0], :2],
            body,
        ),
        root=0,
    )
    if parts is None:
        return None
    offsets = np.cumsum([0] + [p[1].shape[0] for p in parts[:-1]])
    triangles = np.vstack([p[0] + off for p, off in zip(parts, offsets, strict=True)])
    x, disp = np.vstack([p[1] for p in parts]), np.vstack([p[2] for p in parts])
    vertex_body = np.full(x.shape[0], -1.0)
    vertex_body[triangles.ravel()] = np.repeat(np.concatenate([p[3] for p in parts]), 3)
    extent = float(np.max(np.ptp(x[:, :2], axis=0)))
    umax = float(np.max(np.linalg.norm(disp, axis=1), initial=0.0))
    if scale is None:
        scale = 0.1 * extent / umax if umax > 0 else 1.0
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.5), gridspec_kw={"width_ratios": [1.1, 1]})
    deformed = x[:, :2] + scale * disp
    pc = ax.tripcolor(
        deformed[:, 0], deformed[:, 1], triangles, np.linalg.norm(disp, axis=1), shading="gouraud", cmap="viridis"
    )
    ax.triplot(deformed[:, 0], deformed[:, 1], triangles, color="k", lw=0.15, alpha=0.4)
    fig.colorbar(pc, ax=ax, label="|u|")
    slave_body = problem._slave_body  # (the body the slave surface lies on, found by TwoBodyProblem)
    for profile, colour, label, k in (
        (result.slave, "tab:red", "slave", slave_body),
        (result.master, "tab:blue", "master", 1 - slave_body),
    ):
        pts = np.asarray(profile.points)[:, :2]
        own = np.flatnonzero(vertex_body == k)  # (the other body may have a vertex at the same point)
        nodes = own[np.argmin(np.linalg.norm(x[own, None, :2] - pts[None], axis=2), axis=0)]
        moved = pts + scale * disp[nodes]
        ax.plot(moved[:, 0], moved[:, 1], color=colour, lw=1.5, label=label)
        along, axis = _along(pts)
        order = np.argsort(along)
        bx.plot(along[order], -np.asarray(profile.sigma_c)[order], "o-", ms=2.5, color=colour, label=label)
    ax.set_aspect("equal")
    ax.set_title(f"deformed bodies (displacement x{scale:.3g})")
    ax.legend(loc="best", fontsize=8)
    bx.set_xlabel(axis)
    bx.set_ylabel("contact pressure −σ_c")
    bx.set_title("contact pressure on both faces")
    bx.legend()
    bx.grid(True, alpha=0.3)
    fig.suptitle(title)
    return _save(fig, Path(path))


def plot_force_displacement(load_steps: dict, path: str | Path, title: str = "") -> Path:
    """The normal contact force on each side against the stepped support's displacement or traction (its
    component along the last step's; against the step number when the steps do not all lie along the last)."""
    steps = load_steps["steps"]
    kind, quantity = ("support", "displacement") if "support" in load_steps else ("traction", "traction")
    last = np.asarray(steps[-1][quantity], dtype=float)
    direction = last / max(float(np.linalg.norm(last)), np.finfo(float).tiny)
    values = np.asarray([s[quantity] for s in steps], dtype=float)
    across = values - np.outer(values @ direction, direction)  # the part of each step off the last one's line
    along = np.all(np.linalg.norm(across, axis=1) <= 1e-12 * np.abs(values).max())
    d = list(values @ direction) if along else list(range(1, len(steps) + 1))  # (a path that turns: by step)
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(d, [s["normal_force_slave"] for s in steps], "o-", label="slave side")
    ax.plot(d, [s["normal_force_master"] for s in steps], "x--", label="master side")
    frictional = all("friction" in s for s in steps)
    if frictional:  # the tangential force on the slave side, |Σ w_p t_p|
        tangential = [float(np.linalg.norm(s["friction"]["tangential_force"])) for s in steps]
        ax.plot(d, tangential, "s-", ms=4, label="tangential (slave side)")
    label = f"{quantity} of {load_steps[kind]} along ({direction[0]:.3g}, {direction[1]:.3g})"
    ax.set_xlabel(
        label
        if along
        else f"load step ({quantity} of {load_steps[kind]}: {values[0].tolist()} … {values[-1].tolist()})"
    )
    ax.set_ylabel("normal and tangential contact force" if frictional else "normal contact force")
    ax.set_title(title)
    ax.legend()
    ax.grid(True, alpha=0.3)
    return _save(fig, Path(path))
