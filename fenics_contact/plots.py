"""PNG figures: E map, displacement components, contact profiles, convergence history.

Data are gathered to rank 0 (collective), which draws with matplotlib (Agg).
"""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.colors import LogNorm, TwoSlopeNorm  # noqa: E402
from matplotlib.tri import Triangulation  # noqa: E402
from matplotlib.ticker import MaxNLocator  # noqa: E402

from dolfinx import fem  # noqa: E402

from fenics_contact.io import cell_function_of  # noqa: E402

__all__ = ["gather_cells", "plot_cell_field", "plot_displacement", "plot_stress", "plot_contact", "plot_history",
           "render_deformed", "plot_force_indentation"]


def gather_cells(fn: fem.Function, component: int | None = None):
    """(triangulation, values) on rank 0 for a P1 or DG0 function; (None, None) elsewhere.

    P1 values are per cell corner (so Gouraud shading works), DG0 values per cell.
    """
    V = fn.function_space
    msh = V.mesh
    tdim = msh.topology.dim
    ncells = msh.topology.index_map(tdim).size_local
    xy = msh.geometry.x[msh.geometry.dofmaps[0][:ncells]][:, :, :2]  # (N, 3, 2)
    bs = V.dofmap.index_map_bs
    dofs = V.dofmap.list[:ncells]
    comp = 0 if component is None else component
    vals = fn.x.array[dofs * bs + comp]  # (N, 3) for P1, (N, 1) for DG0
    parts = msh.comm.gather((xy, vals), root=0)
    if msh.comm.rank != 0:
        return None, None
    xy = np.concatenate([p[0] for p in parts])
    vals = np.concatenate([p[1] for p in parts])
    n = xy.shape[0]
    tri = Triangulation(xy[:, :, 0].ravel(), xy[:, :, 1].ravel(), np.arange(3 * n).reshape(n, 3))
    return tri, vals


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def plot_cell_field(fn: fem.Function, path: str | Path, *, title: str, log: bool = False) -> Path | None:
    """A DG0 field (e.g. E) as a coloured map."""
    tri, vals = gather_cells(fn)
    if tri is None:
        return None
    fig, ax = plt.subplots(figsize=(5, 4.3))
    vals = np.ravel(vals)
    norm = LogNorm(vmin=vals.min(), vmax=vals.max()) if log and vals.min() > 0 and vals.max() > vals.min() else None
    pc = ax.tripcolor(tri, facecolors=vals, norm=norm, cmap="viridis")
    fig.colorbar(pc, ax=ax)
    ax.set_aspect("equal")
    ax.set_title(title)
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    return _save(fig, Path(path))


def plot_displacement(u: fem.Function, path: str | Path, *, title: str = "") -> Path | None:
    """Both displacement components of a P1 field, side by side."""
    panels = [gather_cells(u, c) for c in range(2)]
    if panels[0][0] is None:
        return None
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.3))
    for ax, (tri, vals), name in zip(axes, panels, ("u_x", "u_y")):
        vals = vals.ravel()
        norm = TwoSlopeNorm(0.0, vals.min(), vals.max()) if vals.min() < 0.0 < vals.max() else None
        pc = ax.tripcolor(tri, vals, shading="gouraud", cmap="RdBu_r", norm=norm)
        fig.colorbar(pc, ax=ax)
        ax.set_aspect("equal")
        ax.set_title(f"{name} {title}".strip())
        ax.set_xlabel("x")
        ax.set_ylabel("y")
    return _save(fig, Path(path))


def plot_stress(sigma: fem.Function, path: str | Path, *, title: str = "") -> Path | None:
    """The three stress components (xx, xy, yy) of a DG stress field, cellwise at the midpoints."""
    cells = cell_function_of(sigma, name="sigma_mid")
    panels = [gather_cells(cells, c) for c in range(3)]
    if panels[0][0] is None:
        return None
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.2))
    for ax, (tri, vals), name in zip(axes, panels, ("σ_xx", "σ_xy", "σ_yy")):
        vals = np.ravel(vals)
        norm = TwoSlopeNorm(0.0, vals.min(), vals.max()) if vals.min() < 0.0 < vals.max() else None
        pc = ax.tripcolor(tri, facecolors=vals, cmap="RdBu_r", norm=norm)
        fig.colorbar(pc, ax=ax)
        ax.set_aspect("equal")
        ax.set_title(f"{name} {title}".strip())
        ax.set_xlabel("x")
        ax.set_ylabel("y")
    return _save(fig, Path(path))


def plot_contact(profiles: dict, path: str | Path, *, comm) -> Path | None:
    """u_c and σ_c along Γ_C for one or more labelled ContactProfiles (cf. the paper's Fig. 5.4)."""
    if comm.rank != 0:
        return None
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    styles = ["-", "--", ":", "-."]
    axis = "y"
    for (label, prof), style in zip(profiles.items(), styles):
        along = prof.y
        if prof.points is not None and len(prof.points):  # along the coordinate Gamma_C spans (x on a top face)
            major = int(np.argmax(np.ptp(prof.points[:, :2], axis=0)))
            along, axis = prof.points[:, major], "xy"[major]
        axes[0].plot(along, prof.u_c, style, label=label)
        axes[1].plot(along, prof.sigma_c, style, label=label)
    axes[0].set_title("normal displacement $u_c$ on $\\Gamma_C$")
    axes[1].set_title("normal stress $\\sigma_c$ on $\\Gamma_C$")
    for ax in axes:
        ax.set_xlabel(axis)
        ax.axhline(0.0, color="k", lw=0.5)
        ax.legend()
    return _save(fig, Path(path))


def plot_history(histories: dict, path: str | Path, *, comm, tol: float | None = None) -> Path | None:
    """Transmission residual (solid), relative change (dotted) and true error (dashed, when known) per
    iteration (cf. Fig. 5.5)."""
    if comm.rank != 0:
        return None
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.set_yscale("log")
    positive = []  # zeros (an exactly glued pair, e.g. a vanishing solution) cannot go on a log axis: left out

    def plot(its, values, style, **kwargs):
        v = np.asarray(values, dtype=float)
        v = np.where(v > 0.0, v, np.nan)
        if np.isfinite(v).any():
            positive.extend(v[np.isfinite(v)])
            ax.plot(its, v, style, **kwargs)

    for k, (label, hist) in enumerate(histories.items()):
        its = np.arange(1, hist.iterations + 1)
        zero = bool(hist.iterations) and hist.residuals[-1] == 0.0
        color = f"C{k}"
        dot = "." if hist.iterations < 20 else ""  # (a lone point of a line without markers is not drawn)
        plot(its, hist.residuals, dot + "-", color=color,
             label=f"{label}: transmission residual")
        if zero:
            ax.plot([], [], "-", color=color, label=f"{label}: transmission residual exactly 0 at iteration "
                    f"{hist.iterations}")
        plot(its, hist.rel_changes, dot + ":", color=color, label=f"{label}: rel. change")
        errs = [r.info.get("e_u") for r in hist.records]
        if all(e is not None for e in errs) and errs:
            plot(its, errs, dot.replace(".", "x") + "--", color=color, label=f"{label}: $e_u$")
    longest = max((h.iterations for h in histories.values()), default=1)
    ax.set_xlim(0.5, max(longest, 1) + 0.5)
    ax.xaxis.set_major_locator(MaxNLocator(integer=True, min_n_ticks=1))
    if tol is not None:
        positive.append(tol)
    if positive:  # (before axhline: a lone horizontal line would autoscale to an empty range)
        ax.set_ylim(0.5 * min(positive), 2.0 * max(positive))
    if tol is not None:
        ax.axhline(tol, color="k", lw=0.5, ls=":")
    ax.set_xlabel("iteration")
    ax.set_ylabel("residual / change / error")
    ax.legend()
    ax.grid(True, which="both", alpha=0.3)
    return _save(fig, Path(path))


def render_deformed(u: fem.Function, path: str | Path, *, scale: float | None = None,
                    title: str = "") -> Path | None:
    """The mesh deformed by u (magnified), coloured by |u|, rendered off-screen with pyvista (rank 0)."""
    import os

    if not os.environ.get("DISPLAY"):  # off-screen OpenGL, no X server needed
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import pyvista

    from dolfinx import plot

    V = u.function_space
    msh = V.mesh
    topology, cell_types, x = plot.vtk_mesh(V)
    values = np.zeros((x.shape[0], 3))
    values[:, : msh.geometry.dim] = u.x.array.reshape(x.shape[0], V.dofmap.index_map_bs)
    parts = msh.comm.gather((topology, cell_types, x, values), root=0)
    if msh.comm.rank != 0:
        return None
    offsets = np.cumsum([0] + [p[2].shape[0] for p in parts[:-1]])
    cells = []
    for (top, _, _, _), off in zip(parts, offsets):
        top = top.reshape(-1, 4).copy()
        top[:, 1:] += off
        cells.append(top.ravel())
    grid = pyvista.UnstructuredGrid(np.concatenate(cells), np.concatenate([p[1] for p in parts]),
                                   np.concatenate([p[2] for p in parts]))
    disp = np.concatenate([p[3] for p in parts])
    grid.point_data["|u|"] = np.linalg.norm(disp, axis=1)
    if scale is None:
        umax = float(np.max(np.abs(disp)))
        scale = 0.1 / umax if umax > 0 else 1.0
    warped = grid.copy()
    warped.points = grid.points + scale * disp
    pyvista.OFF_SCREEN = True
    plotter = pyvista.Plotter(off_screen=True, window_size=(900, 800))
    plotter.add_mesh(grid, style="wireframe", color="lightgray", opacity=0.3)
    plotter.add_mesh(warped, scalars="|u|", show_edges=False, cmap="viridis")
    plotter.add_mesh(pyvista.Line((1.0, -0.02, 0.0), (1.0, 1.02, 0.0)), color="red", line_width=4)  # obstacle
    plotter.add_text(f"{title} (displacement x{scale:.3g})".strip(), font_size=10)
    plotter.view_xy()
    plotter.screenshot(str(path))
    plotter.close()
    return Path(path)


def plot_force_indentation(curves: dict, path: str | Path, *, comm) -> Path | None:
    """Force against indentation depth, one line per labelled curve ({"direction", "steps": [{depth, force}]})."""
    if comm.rank != 0:
        return None
    fig, ax = plt.subplots(figsize=(6, 4))
    for label, curve in curves.items():
        depths = [s["depth"] for s in curve["steps"]]
        forces = [s["force"] for s in curve["steps"]]
        ax.plot(depths, forces, "o-", label=label)
    ax.set_xlabel("indentation depth")
    ax.set_ylabel("contact force (along the indentation)")
    ax.legend()
    ax.grid(True, alpha=0.3)
    return _save(fig, Path(path))
