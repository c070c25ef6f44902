"""PNG figures: E map, displacement components, contact profiles, convergence history.

Data are gathered to rank 0 (collective), which draws with matplotlib (Agg).
"""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
from typing import NamedTuple  # noqa: E402

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from dolfinx import fem, la  # noqa: E402
from matplotlib.colors import LogNorm, TwoSlopeNorm  # noqa: E402
from matplotlib.ticker import MaxNLocator  # noqa: E402
from matplotlib.tri import Triangulation  # noqa: E402

from fenics_contact.io import cell_function_of  # noqa: E402
from fenics_contact.problem.obstacles import Circle, Translated  # noqa: E402

__all__ = [
    "gather_cells",
    "plot_cell_field",
    "plot_displacement",
    "plot_stress",
    "HertzCurve",
    "hertz_curve_for",
    "plot_contact",
    "plot_history",
    "nodal_average",
    "obstacle_outline",
    "render_deformed",
    "plot_force_indentation",
]


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


class HertzCurve(NamedTuple):
    """What the plane-strain Hertz pressure of a contact profile needs: cylinder radius, E, ν of the body at
    the contact, and the coordinate (along Γ_C) of the cylinder's centre."""

    radius: float
    E: float
    nu: float
    centre: float


def hertz_curve_for(obstacle, points: np.ndarray | None, E: float, nu: float) -> HertzCurve | None:
    """The Hertz comparison of a profile when the obstacle is a (moved) circle and Γ_C is straight, else None."""
    base, shift = obstacle, np.zeros(2)
    while isinstance(base, Translated):
        shift, base = shift + np.asarray(base.shift), base.base
    if not isinstance(base, Circle) or points is None or len(points) < 3:
        return None
    xy = np.asarray(points)[:, :2]
    d = xy - xy.mean(axis=0)
    _, sv, vt = np.linalg.svd(d, full_matrices=False)
    if sv[1] > 1e-9 * max(sv[0], 1e-300):  # Γ_C is not a straight segment
        return None
    major = int(np.argmax(np.ptp(xy, axis=0)))
    return HertzCurve(base.radius, E, nu, float(np.asarray(base.centre)[major] + shift[major]))


def plot_contact(profiles: dict, path: str | Path, *, comm, hertz: HertzCurve | None = None) -> Path | None:
    """Normal displacement u_c and contact pressure p = −σ_c along Γ_C for labelled ContactProfiles, with the
    plane-strain Hertz pressure for the force of the first profile when ``hertz`` is given (a cylinder on a
    straight Γ_C: E* = E/(1 − ν²), a = 2√(RF/(πE*)), p = p₀√(1 − x²/a²), p₀ = 2F/(πa))."""
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
        axes[1].plot(along, -np.asarray(prof.sigma_c), style, label=label)
    if hertz is not None and profiles:
        first = next(iter(profiles.values()))
        force = first.force
        if force > 0:
            E_star = hertz.E / (1.0 - hertz.nu**2)
            a = 2.0 * np.sqrt(hertz.radius * force / (np.pi * E_star))
            p0 = 2.0 * force / (np.pi * a)
            x = hertz.centre + np.linspace(-1.2 * a, 1.2 * a, 241)
            axes[1].plot(
                x,
                p0 * np.sqrt(np.maximum(1.0 - ((x - hertz.centre) / a) ** 2, 0.0)),
                "k:",
                lw=1.2,
                label=f"Hertz (a = {a:.3g}, p₀ = {p0:.3g})",
            )
    axes[0].set_title("normal displacement $u_c$ on $\\Gamma_C$")
    axes[1].set_title("contact pressure $p = -\\sigma_c$ on $\\Gamma_C$")
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
        plot(its, hist.residuals, dot + "-", color=color, label=f"{label}: transmission residual")
        if zero:
            ax.plot(
                [],
                [],
                "-",
                color=color,
                label=f"{label}: transmission residual exactly 0 at iteration {hist.iterations}",
            )
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


def nodal_average(u: fem.Function) -> fem.Function:
    """A discontinuous P1 vector field (the mixed displacement) as a continuous one: at every vertex the mean of
    the values the cells around it give (collective)."""
    msh = u.function_space.mesh
    gdim = msh.geometry.dim
    V = fem.functionspace(msh, ("Lagrange", 1, (gdim,)))
    tdim = msh.topology.dim
    n_cells = msh.topology.index_map(tdim).size_local
    cell_dofs_dg = u.function_space.dofmap.list[:n_cells]
    cell_dofs_p1 = V.dofmap.list[:n_cells]  # (the same reference vertex order as the DG P1 dofs)
    bs = V.dofmap.index_map_bs
    total = la.vector(V.dofmap.index_map, bs)
    count = la.vector(V.dofmap.index_map, bs)
    for c in range(bs):
        np.add.at(total.array, bs * cell_dofs_p1.ravel() + c, u.x.array[bs * cell_dofs_dg.ravel() + c])
        np.add.at(count.array, bs * cell_dofs_p1.ravel() + c, 1.0)
    total.scatter_reverse(la.InsertMode.add)
    count.scatter_reverse(la.InsertMode.add)
    out = fem.Function(V, name=u.name)
    n = V.dofmap.index_map.size_local * bs
    out.x.array[:n] = total.array[:n] / np.maximum(count.array[:n], 1.0)
    out.x.scatter_forward()
    return out


def obstacle_outline(
    obstacle, box: tuple[float, float, float, float], *, scale: float = 1.0, resolution: int = 600
) -> list[np.ndarray]:
    """Polylines (k, 2) of the obstacle's boundary d = 0 inside ``box`` (x0, x1, y0, y1): the zero contour of its
    signed distance, any obstacle. Its rigid motion (``Translated``) is magnified by ``scale``, as the
    displacements of a deformed plot are, so that the drawn obstacle meets the drawn body where they touch."""
    shift = np.zeros(2)
    base = obstacle
    while isinstance(base, Translated):
        shift, base = shift + np.asarray(base.shift), base.base
    x0, x1, y0, y1 = box
    X, Y = np.meshgrid(np.linspace(x0, x1, resolution), np.linspace(y0, y1, resolution))
    points = np.vstack([X.ravel() - scale * shift[0], Y.ravel() - scale * shift[1], np.zeros(X.size)])
    with np.errstate(invalid="ignore"):
        d = np.asarray(base.distance(points), dtype=float).reshape(X.shape)
    if not (np.nanmin(d, initial=np.inf) < 0.0 < np.nanmax(d, initial=-np.inf)):
        return []
    fig, ax = plt.subplots()
    lines = [np.asarray(seg) for seg in ax.contour(X, Y, d, levels=[0.0]).allsegs[0] if len(seg) > 1]
    plt.close(fig)
    return lines


def render_deformed(
    u: fem.Function,
    path: str | Path,
    *,
    scale: float | None = None,
    title: str = "",
    obstacle=None,
    wall: np.ndarray | None = None,
) -> Path | None:
    """The mesh deformed by u (magnified), coloured by |u|, with the obstacle (its motion magnified alike), or
    with ``wall`` (the Γ_C points in order: a wall flush with Γ_C), rendered off-screen with pyvista (rank 0)."""
    import os

    if not os.environ.get("DISPLAY"):  # off-screen OpenGL, no X server needed
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import pyvista
    from dolfinx import plot

    if u.function_space.ufl_element().discontinuous:
        u = nodal_average(u)
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
    grid = pyvista.UnstructuredGrid(
        np.concatenate(cells), np.concatenate([p[1] for p in parts]), np.concatenate([p[2] for p in parts])
    )
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
    if obstacle is not None:
        lo, hi = warped.points.min(axis=0), warped.points.max(axis=0)
        margin = 0.15 * float(np.max(hi - lo))
        box = (lo[0] - margin, hi[0] + margin, lo[1] - margin, hi[1] + margin)
        for line in obstacle_outline(obstacle, box, scale=scale):
            plotter.add_mesh(
                pyvista.lines_from_points(np.column_stack([line, np.zeros(len(line))])), color="red", line_width=4
            )
    elif wall is not None and len(wall) > 1:
        plotter.add_mesh(
            pyvista.lines_from_points(np.column_stack([np.asarray(wall)[:, :2], np.zeros(len(wall))])),
            color="red",
            line_width=4,
        )
    plotter.add_text(f"{title} (displacement and obstacle motion x{scale:.3g})".strip(), font_size=10)
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
