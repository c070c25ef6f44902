"""The boundary of the primal P1 subproblem: u = u_D on Γ_D, the tractions on Γ_N and the nodal contact geometry on Γ_C.

u_D is imposed strongly (Newton works with homogeneous increments; the iterate carries u_D on the Γ_D
DOFs), so is u_i = 0 on a roller (symmetry) plane x_i = c; the tractions t_k are P1-interpolated and
enter the load, the other facets are traction free.  The contact direction ν and the gap g are nodal (P1)
on Γ_C: the obstacle's at the Γ_C vertices, or for a wall flush with Γ_C (no obstacle) the body's nodal
normal (facet normals averaged with the vertex weights) and g = 0.  One ν per node keeps the active set a
set of nodes on a curved Γ_C too.
"""

import dolfinx.fem.petsc
import numpy as np
import ufl
from dolfinx import fem
from dolfinx import mesh as dmesh
from mpi4py import MPI
from petsc4py import PETSc

from fenics_contact.errors import InputError
from fenics_contact.fem.contact import ContactProfile, profile_order
from fenics_contact.fem.contact_boundary import contact_boundary_present, obstacle_at_nodes
from fenics_contact.problem.boundary import BoundaryConditions, neumann_groups
from fenics_contact.problem.obstacles import Obstacle
from fenics_contact.problem.tags import Boundary

__all__ = ["NodalContactGeometry", "PrimalBoundaryData", "roller_conditions"]


class PrimalBoundaryData:
    """u = u_D on Γ_D and u_i = 0 on the roller planes (``bcs``: the homogeneous conditions of the Newton
    increments) and the tractions on Γ_N.

    ``traction_terms``: (t_k, ds_k) for every traction group with facets on this mesh (t_k in P1, also in
    ``tractions``); ``dirichlet_dofs`` / ``dirichlet_q``: the Γ_D DOFs of V and of the scalar P1 space Q.
    """

    def __init__(
        self, V: fem.FunctionSpace, Q: fem.FunctionSpace, facet_tags: dmesh.MeshTags, boundary: BoundaryConditions
    ) -> None:
        msh = V.mesh
        tdim = msh.topology.dim
        gdim = msh.geometry.dim
        dirichlet = facet_tags.find(Boundary.GAMMA_D)
        dofs = fem.locate_dofs_topological(V, tdim - 1, dirichlet)
        self.bcs = [fem.dirichletbc(np.zeros(gdim, dtype=PETSc.ScalarType), dofs, V)]
        self.bcs += roller_conditions(V, boundary.rollers)
        self.dirichlet_dofs = dofs
        self.dirichlet_q = fem.locate_dofs_topological(Q, tdim - 1, dirichlet)
        self.u_D: fem.Function | None = None
        if boundary.displacement is not None:
            self.u_D = fem.Function(V, name="u_D")
            self.u_D.interpolate(boundary.displacement)
            self.u_D.x.scatter_forward()
        ds = ufl.Measure("ds", domain=msh, subdomain_data=facet_tags)
        present = set(msh.comm.allreduce(neumann_groups(facet_tags)))
        self.tractions: list[fem.Function] = []
        self.traction_terms: list = []
        for tag, name, field in boundary.traction_tags():
            if tag not in present:
                continue  # on another subdomain
            t = fem.Function(V, name=f"t_{name}")
            t.interpolate(field)
            t.x.scatter_forward()
            self.tractions.append(t)
            self.traction_terms.append((t, ds(tag)))

    def set_lifting(self, u: fem.Function) -> None:
        """u ← u_D on the Γ_D DOFs and 0 elsewhere (the state every cold Newton solve starts from)."""
        u.x.array[:] = 0.0
        if self.u_D is not None:
            fem.dirichletbc(self.u_D, self.dirichlet_dofs).set(u.x.array)
        u.x.scatter_forward()


def roller_conditions(V: fem.FunctionSpace, rollers) -> list[fem.DirichletBC]:
    """u_i = 0 on the exterior facets in each plane x_i = c of ``rollers`` ((i, c) pairs; collective).

    The plane is matched to 1e-10 of the mesh's extent; InputError if no exterior facet lies in it or the
    axis exceeds the dimension."""
    msh = V.mesh
    tdim, gdim = msh.topology.dim, msh.geometry.dim
    if not rollers:
        return []
    x = msh.geometry.x[:, :gdim]
    local = float(np.max(np.ptp(x, axis=0))) if x.shape[0] else 0.0
    tol = 1e-10 * msh.comm.allreduce(local, op=MPI.MAX)
    bcs = []
    for axis, value in rollers:
        if axis >= gdim:
            raise InputError(f"a roller plane x_{axis} = {value:g} needs a {axis + 1}D mesh; this one is {gdim}D")
        facets = dmesh.locate_entities_boundary(msh, tdim - 1, lambda p, a=axis, c=value: np.abs(p[a] - c) <= tol)
        if msh.comm.allreduce(int(facets.size), op=MPI.SUM) == 0:
            raise InputError(f"no exterior facet lies in the roller plane x_{axis} = {value:g}")
        Vi = V.sub(axis)
        dofs = fem.locate_dofs_topological(Vi, tdim - 1, facets)
        bcs.append(fem.dirichletbc(PETSc.ScalarType(0.0), dofs, Vi))
    return bcs


class NodalContactGeometry:
    """Nodal contact direction ν (vector P1 ``nu``) and gap g (P1 ``gap``) at the Γ_C vertices.

    ``weights``: the vertex weights ∫_ΓC φ_p ds; ``surface_normal``: the body's nodal outward normal at the
    Γ_C vertices; Γ_D vertices (``dirichlet_q``, clamped corners) are not contact nodes.  InputError if an
    obstacle is given and Γ_C has no facets.
    """

    def __init__(
        self,
        V: fem.FunctionSpace,
        Q: fem.FunctionSpace,
        facet_tags: dmesh.MeshTags,
        ds_c,
        dirichlet_q: np.ndarray,
        obstacle: Obstacle | None,
    ) -> None:
        msh = V.mesh
        self.V, self.Q, self.dirichlet_q = V, Q, dirichlet_q
        self.comm = msh.comm
        tdim = msh.topology.dim
        contact = facet_tags.find(Boundary.GAMMA_C)
        contact_boundary_present(self.comm, contact, obstacle)
        self.contact_q = fem.locate_dofs_topological(Q, tdim - 1, contact)
        self.nu = fem.Function(V, name="nu")
        self.gap = fem.Function(Q, name="gap")
        q = ufl.TestFunction(Q)
        v = ufl.TestFunction(V)
        w = dolfinx.fem.assemble_vector(fem.form(q * ds_c))
        w.scatter_reverse(dolfinx.la.InsertMode.add)
        w.scatter_forward()
        N = dolfinx.fem.assemble_vector(fem.form(ufl.dot(v, ufl.FacetNormal(msh)) * ds_c))
        N.scatter_reverse(dolfinx.la.InsertMode.add)
        N.scatter_forward()
        gdim = msh.geometry.dim
        nodes = self.contact_q
        Nn = N.array.reshape(-1, gdim)[nodes]
        self.surface_normal = Nn / np.linalg.norm(Nn, axis=1)[:, None] if nodes.size else Nn
        self.weights = w.array
        self.points = Q.tabulate_dof_coordinates()  #: the coordinates of Q's DOFs (the mesh does not move)
        self.obstacle: Obstacle | None = None
        self.set_obstacle(obstacle)

    def set_obstacle(self, obstacle: Obstacle | None) -> bool:
        """ν and g at the Γ_C vertices for ``obstacle`` (collective); True when ν changed (ν enters the Jacobian)."""
        nodes = self.contact_q
        gdim = self.V.mesh.geometry.dim
        points = self.points[nodes]
        g, nu = obstacle_at_nodes(obstacle, points, self.surface_normal, comm=self.comm)
        previous = self.nu.x.array.copy()
        self.nu.x.array[:] = 0.0
        self.nu.x.array.reshape(-1, gdim)[nodes] = nu
        self.gap.x.array[:] = 0.0
        self.gap.x.array[nodes] = g
        # ghosts take their owner's ν and g: each rank evaluates the obstacle at its own copy of a node's
        # coordinates (pushed forward through a different cell, they can differ in the last bit), and the
        # facets at a node must see one u·ν − g, or near u·ν = g the node is active on one facet only
        self.nu.x.scatter_forward()
        self.gap.x.scatter_forward()
        same_direction = self.comm.allreduce(bool(np.array_equal(previous, self.nu.x.array)), op=MPI.LAND)
        self.obstacle = obstacle
        return not same_direction

    def owned_nodes(self) -> np.ndarray:
        """Owned Γ_C vertices off Γ_D with a positive weight (indices into Q's DOFs)."""
        nloc = self.Q.dofmap.index_map.size_local
        w = self.weights
        on = np.zeros(nloc, dtype=bool)
        on[self.contact_q[self.contact_q < nloc]] = True
        on &= w[:nloc] > 0.0
        on[self.dirichlet_q[self.dirichlet_q < nloc]] = False  # clamped corners: not contact
        return np.flatnonzero(on)

    def nodes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(node = block index of u, ν_p (k, gdim), vertex weight w_p, gap g_p) at the ``owned_nodes``."""
        nodes = self.owned_nodes()
        gdim = self.V.mesh.geometry.dim
        nu = self.nu.x.array.reshape(-1, gdim)[nodes].copy()
        return nodes, nu, self.weights[nodes].copy(), self.gap.x.array[nodes].copy()

    def profile(self, u: fem.Function, reaction: np.ndarray) -> ContactProfile:
        """u_c = u·ν − g and σ_c = (R·ν_p)/w_p at the ``owned_nodes`` of all ranks, in ``profile_order``
        (``reaction``: the assembled residual without the contact term, local entries)."""
        on = self.owned_nodes()
        w = self.weights
        gdim = self.V.mesh.geometry.dim
        normal = self.nu.x.array.reshape(-1, gdim)[on]
        gap = self.gap.x.array[on]
        u_c = np.sum(u.x.array.reshape(-1, gdim)[on] * normal, axis=1) - gap
        sigma_c = np.sum(reaction.reshape(-1, gdim)[on] * normal, axis=1) / w[on]
        points = self.points[on, :gdim]
        comm = self.comm
        points, u_c, sigma_c, weights, normal, gap = (
            np.concatenate(comm.allgather(a)) for a in (points, u_c, sigma_c, w[on], normal, gap)
        )
        order = profile_order(points)
        return ContactProfile(
            points[order, 1], u_c[order], sigma_c[order], points[order], weights[order], normal[order], gap[order]
        )
