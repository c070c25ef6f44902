"""Interface (γ) bookkeeping: submeshes of Ω₁ and Ω₂, transfers, nodal Robin coefficient α.

The Robin data are nodal on γ (vertex quadrature), so they are stored as values
at the *owned* γ DOFs of a P1 space on the parent mesh, and copied into P1
functions on each submesh when a subproblem needs them.
"""

from typing import NamedTuple

import basix.ufl
import numpy as np
import ufl
from dolfinx import fem, la
from dolfinx import mesh as dmesh
from mpi4py import MPI

from fenics_contact.errors import InputError
from fenics_contact.problem.fields import SubmeshTransfer
from fenics_contact.problem.geometry import ContactMesh
from fenics_contact.problem.tags import Boundary, Subdomain

__all__ = ["InterfaceSpace", "Part", "part_rollers", "robin_coefficient", "split_mesh", "sub_to_parent_dofs"]


class Part(NamedTuple):
    """A subdomain submesh with its facet tags and cell map to the parent."""

    mesh: dmesh.Mesh
    facet_tags: dmesh.MeshTags
    cell_map: dmesh.EntityMap
    vertex_map: dmesh.EntityMap


def split_mesh(cm: ContactMesh) -> tuple[Part, Part]:
    """Submeshes Ω₁ and Ω₂ of a tagged mesh, with the facet tags transferred."""
    tdim = cm.mesh.topology.dim
    parts = []
    for sub in (Subdomain.OMEGA1, Subdomain.OMEGA2):
        cells = cm.cell_tags.find(sub)
        msh, cmap, vmap, _ = dmesh.create_submesh(cm.mesh, tdim, cells)
        ft = dmesh.transfer_meshtags_to_submesh(cm.facet_tags, msh, vmap, cmap)
        parts.append(Part(msh, ft, cmap, vmap))
    return parts[0], parts[1]


def part_rollers(part: Part, rollers) -> tuple[tuple[int, float], ...]:
    """The roller planes x_i = c of ``rollers`` that hold exterior facets of the part (collective): the part's
    own rollers. InputError when a plane holds a facet of γ (a roller on γ would constrain one side of the
    interface only)."""
    msh = part.mesh
    tdim = msh.topology.dim
    x = msh.geometry.x[:, : msh.geometry.dim]
    tol = 1e-10 * msh.comm.allreduce(float(np.max(np.ptp(x, axis=0))) if x.shape[0] else 0.0, op=MPI.MAX)
    gamma = part.facet_tags.find(Boundary.INTERFACE)
    own = []
    for axis, value in rollers:
        if axis >= msh.geometry.dim:
            own.append((axis, value))  # (refused with its message by the subproblem's roller conditions)
            continue
        facets = dmesh.locate_entities_boundary(msh, tdim - 1, lambda p, a=axis, c=value: np.abs(p[a] - c) <= tol)
        on_gamma = np.isin(facets, gamma)
        counts = msh.comm.allreduce(np.array([np.count_nonzero(on_gamma), np.count_nonzero(~on_gamma)]), op=MPI.SUM)
        if counts[0]:
            raise InputError(
                f"the roller plane x_{axis} = {value:g} holds {counts[0]} facets of the interface γ between Omega1 "
                "and Omega2: a roller must lie on the outer boundary (move γ or the plane)"
            )
        if counts[1]:
            own.append((axis, value))
    return tuple(own)


class InterfaceSpace:
    """Nodal P1 data on γ: owned interface DOFs of a parent space and transfers to both parts."""

    def __init__(self, cm: ContactMesh, parts: tuple[Part, Part], *, shape: tuple[int, ...]) -> None:
        msh = cm.mesh
        tdim = msh.topology.dim
        self.comm = msh.comm
        el = basix.ufl.element("Lagrange", msh.basix_cell(), 1, shape=shape)
        self.V = fem.functionspace(msh, el)
        self.bs = self.V.dofmap.index_map_bs
        blocks = fem.locate_dofs_topological(self.V, tdim - 1, cm.facet_tags.find(Boundary.INTERFACE))
        blocks = blocks[blocks < self.V.dofmap.index_map.size_local]
        self.dofs = (self.bs * blocks[:, None] + np.arange(self.bs)).ravel()
        self.spaces = [fem.functionspace(p.mesh, el) for p in parts]
        self.transfers = [SubmeshTransfer(self.V, Vs, p.cell_map) for Vs, p in zip(self.spaces, parts)]
        self._scratch = fem.Function(self.V)
        self._at = self._serial_positions()
        self.coordinates = self.V.tabulate_dof_coordinates()[blocks]
        #: vertex-quadrature weight w_p of the node of every owned interface value: ∫_γ w·v ds = Σ_p w_p w(p)·v(p)
        self.weights = self._vertex_weights(parts[0])

    def _serial_positions(self) -> list[np.ndarray] | None:
        """On one process, the position in each part's space of every interface value (the transfers are then
        copies of those entries, ``to_part`` and ``from_part``); None under MPI."""
        if self.comm.size > 1:
            return None
        at = []
        for transfer in self.transfers:
            lookup = np.full(self._scratch.x.array.size, -1, dtype=np.int64)
            lookup[transfer.parent] = transfer.sub
            at.append(lookup[self.dofs])
        return at if all(np.all(a >= 0) for a in at) else None

    def _vertex_weights(self, part: Part) -> np.ndarray:
        """w_p = ∫_γ φ_p ds for the P1 hat functions, assembled on Ω₁ (where γ is a boundary)."""
        V = self.spaces[0]
        v = ufl.TestFunction(V)
        ones = ufl.as_vector([1.0] * self.bs)
        ds = ufl.Measure("ds", domain=part.mesh, subdomain_data=part.facet_tags)
        vec = fem.assemble_vector(fem.form(ufl.dot(v, ones) * ds(Boundary.INTERFACE)))
        vec.scatter_reverse(la.InsertMode.add)
        w = fem.Function(V)
        w.x.array[:] = vec.array
        w.x.scatter_forward()
        return self.from_part(w, 0)

    def gather(self, values: np.ndarray) -> np.ndarray:
        """All owned interface values of every rank, concatenated in rank order (the global numbering)."""
        return np.concatenate(self.comm.allgather(np.asarray(values)))

    def local(self, values: np.ndarray) -> np.ndarray:
        """This rank's owned part of globally numbered interface values (inverse of ``gather``)."""
        offset = self.comm.exscan(self.size) or 0
        return np.asarray(values[offset : offset + self.size])

    @property
    def size(self) -> int:
        """Local number of owned interface values."""
        return self.dofs.size

    def to_part(self, values: np.ndarray, i: int, out: fem.Function) -> None:
        """out (on part i) ← nodal interface values, zero off γ (collective)."""
        if self._at is not None:
            out.x.array[:] = 0.0
            out.x.array[self._at[i]] = values
            return
        self._scratch.x.array[:] = 0.0
        self._scratch.x.array[self.dofs] = values
        self._scratch.x.scatter_forward()
        self.transfers[i].to_sub(self._scratch, out)

    def from_part(self, u: fem.Function, i: int) -> np.ndarray:
        """Owned interface values of a function on part i (collective)."""
        if self._at is not None:
            return u.x.array[self._at[i]].copy()
        self._scratch.x.array[:] = 0.0
        self.transfers[i].to_parent(u, self._scratch)
        return self._scratch.x.array[self.dofs].copy()

    def from_parent(self, u: fem.Function) -> np.ndarray:
        """Owned interface values of a function on the parent space."""
        return u.x.array[self.dofs].copy()


def _parse_factor(token: str, h: float) -> tuple[float, bool | str, bool]:
    """One factor of an α spelling: a number, 'E', 'Emin', 'sqrt-h' or 'h^p' → (value, 'E' / 'Emin' / False,
    whether it is a symbol rather than a number)."""
    if token == "E":
        return 1.0, True, True
    if token.endswith("Emin"):
        return float(token[:-4] or 1.0), "Emin", True
    if token == "sqrt-h":
        return h**0.5, False, True
    if token.startswith("h^"):
        power = token[2:].strip("()")
        num, _, den = power.partition("/")
        return h ** (float(num) / float(den or 1)), False, True
    if token.endswith("E"):
        return float(token[:-1]), True, True
    return float(token), False, False


def robin_coefficient(
    alpha: float | str, E: fem.Function, space: "InterfaceSpace", h: float, length: float = 1.0
) -> np.ndarray:
    """Nodal α on the owned interface DOFs from a number or a product spelling.

    ``alpha`` is a number (a stiffness per length in the data's units, used as given), or a product of factors
    joined by ``*``: numbers, ``h^p`` (e.g. ``h^-1/2``), ``sqrt-h`` (= h^½), ``E``, where E stands for
    E_p, the area- (in 3D volume-) weighted mean of Young's modulus over the cells touching node p,
    and ``Emin``, the smallest E_p on γ (one number for all nodes).
    Examples: ``"1"``, ``"h^-1/2"``, ``"E"``, ``"2E"``, ``"E*h^-1/2"``, ``"Emin*h^-1/2"``.

    Units: in a spelling with a symbol (h, E, Emin), h is the relative mesh size h/L_ref and the product is
    divided by L_ref (``length``, the body's size), so α = E (h/L_ref)^-½ / L_ref = E/√(h L_ref) is a stress per
    length and the same spelling gives the same relative answers in any unit of length (L_ref = 1 on the unit
    square: α = E h^-½ there).  A spelling of numbers only is a number.
    """
    if not (np.isfinite(length) and length > 0):
        raise InputError(f"the reference length L_ref must be a finite number > 0, got {length!r}")
    scale, with_E, with_Emin, symbolic = 1.0, False, False, False
    if isinstance(alpha, str):
        try:
            for token in alpha.replace(" ", "").split("*"):
                value, kind, symbol = _parse_factor(token, h / length)
                scale *= value
                with_E |= kind is True
                with_Emin |= kind == "Emin"
                symbolic |= symbol
        except (ValueError, ZeroDivisionError):
            raise InputError(
                f"cannot read alpha={alpha!r}: give a number or a product like 'h^-1/2', 'sqrt-h', 'E', '2E*h^-1/2'"
            ) from None
        if symbolic:
            scale /= length
    else:
        try:
            scale = float(alpha)
        except (TypeError, ValueError):
            raise InputError(
                f"the transmission coefficient must be a number or a string like 'E*h^-1/2', got {alpha!r}"
            ) from None
    if not (np.isfinite(scale) and scale > 0):
        raise InputError(f"the transmission coefficient must be > 0, got {alpha!r}")
    if with_E and with_Emin:
        raise InputError(f"alpha={alpha!r}: use E (nodal) or Emin (its smallest value on γ), not both")
    if not (with_E or with_Emin):
        return np.full(space.size, scale)
    v = ufl.TestFunction(space.V)
    ones = ufl.as_vector([1.0] * space.bs)
    num = fem.assemble_vector(fem.form(E * ufl.dot(v, ones) * ufl.dx))
    den = fem.assemble_vector(fem.form(ufl.dot(v, ones) * ufl.dx))
    for vec in (num, den):
        vec.scatter_reverse(la.InsertMode.add)
    E_p = num.array[space.dofs] / den.array[space.dofs]
    if with_Emin:
        lowest = space.comm.allreduce(float(E_p.min(initial=np.inf)), op=MPI.MIN)
        return np.full(space.size, scale * lowest)
    return scale * E_p


def sub_to_parent_dofs(
    part: Part, V_sub: fem.FunctionSpace, V_parent: fem.FunctionSpace
) -> tuple[np.ndarray, np.ndarray]:
    """(sub, parent) indices of the same DOFs of a discontinuous blocked space (checked by coordinates)."""
    tdim = part.mesh.topology.dim
    ncell = part.mesh.topology.index_map(tdim).size_local
    cells = np.arange(ncell, dtype=np.int32)
    pcells = np.asarray(part.cell_map.sub_topology_to_topology(cells, False), dtype=np.int32)
    bs = V_sub.dofmap.index_map_bs
    ds, dp = V_sub.dofmap.list[cells].ravel(), V_parent.dofmap.list[pcells].ravel()
    xs, xp = V_sub.tabulate_dof_coordinates()[ds], V_parent.tabulate_dof_coordinates()[dp]
    if not np.allclose(xs, xp, atol=1e-12 * float(np.max(np.abs(xp), initial=0.0))):  # (relative: any length unit)
        raise RuntimeError("submesh and parent cells do not share their local DOF layout")
    sub = (bs * ds.astype(np.int64)[:, None] + np.arange(bs)).ravel()
    par = (bs * dp.astype(np.int64)[:, None] + np.arange(bs)).ravel()
    return sub, par
