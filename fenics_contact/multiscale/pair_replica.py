"""A distributed two-body problem as the same serial problem on every rank, and its solution back on the ranks.

Algorithm 3 for a pair (``multiscale.pair``) builds each bulk's CEM-GMsFEM space on a serial submesh.  Under MPI
every rank builds the serial copy of the whole mesh (``multiscale.replica.SerialReplica``: owned cells, vertex
coordinates and facet tags allgathered once), with the bodies' cell tags and their DG0 E, ν and body force carried
cell by cell (so a law known only on the distributed mesh, such as a case file's per-group values, reaches the
copy unchanged); supports, tractions and the contact pair are the problem's.  Every rank then solves the same
serial pair; the displacement goes back to the distributed P1 space through the copy's vertex numbering (local:
every rank holds every value), the strip cells to the rank's owned cells, and the contact profiles, forces and
stick/slip state (the same on every rank) are kept as they are.

Cost: every rank does the whole serial solve (offline phase of both bulks, both strips, the interface Newton
method) and holds the whole mesh: no speed-up over one process, one Allgather of the mesh, memory of the serial
run on each rank.  A load step's ``state`` holds the rank's owned displacement DOFs (as Algorithm 1's under MPI)
and the copy's friction anchors and interface data (to be handed to the next step of the same method).
"""

import dataclasses

import basix.ufl
import numpy as np
import scipy.spatial
from dolfinx import fem
from dolfinx import mesh as dmesh

from fenics_contact.fem.two_body import PairState
from fenics_contact.hybrid.two_body import TwoBodyHybridResult
from fenics_contact.multiscale.replica import SerialReplica
from fenics_contact.problem.pair import Body, TwoBodyProblem

__all__ = ["PairReplica"]


def _cell_values(fn: fem.Function, n_cells: int) -> np.ndarray:
    """The values of a DG0 field on the first ``n_cells`` cells (rows of its block size)."""
    bs = fn.function_space.dofmap.index_map_bs
    values = fn.x.array.reshape(-1, bs)[fn.function_space.dofmap.list[:n_cells, 0]]
    return values[:, 0] if bs == 1 else values


def _cell_law(msh: dmesh.Mesh, values: np.ndarray):
    """x (3, N) -> the value of the cell whose midpoint is x (the problem evaluates its laws at cell midpoints)."""
    tdim = msh.topology.dim
    cells = np.arange(msh.topology.index_map(tdim).size_local, dtype=np.int32)
    tree = scipy.spatial.cKDTree(dmesh.compute_midpoints(msh, tdim, cells))

    def law(x: np.ndarray) -> np.ndarray:
        index = tree.query(x.T)[1]
        return values[index].T

    return law


class PairReplica:
    """The serial copy of a distributed ``TwoBodyProblem`` (``problem``: on ``MPI.COMM_SELF``, the same on every
    rank) with the transfers of states and results between the two."""

    def __init__(self, problem: TwoBodyProblem) -> None:
        msh = problem.mesh
        tdim, gdim = msh.topology.dim, msh.geometry.dim
        imap = msh.topology.index_map(tdim)
        n_owned = imap.size_local
        self.V = fem.functionspace(msh, basix.ufl.element("Lagrange", msh.basix_cell(), 1, shape=(gdim,)))
        tags = np.full(n_owned + imap.num_ghosts, -1, dtype=np.int32)
        tags[problem.cell_tags.indices] = problem.cell_tags.values
        fields = problem.fields
        data = {"tag": tags[:n_owned], "E": _cell_values(fields.E, n_owned), "nu": _cell_values(fields.nu, n_owned)}
        data["f"] = _cell_values(fields.f, n_owned)
        self.replica = SerialReplica(msh, problem.facet_tags, self.V, data)
        copy = self.replica.mesh
        values = self.replica.cell_data
        n_cells = copy.topology.index_map(tdim).size_local
        cell_tags = dmesh.meshtags(copy, tdim, np.arange(n_cells, dtype=np.int32), values["tag"].astype(np.int32))
        E, nu, f = (_cell_law(copy, values[name]) for name in ("E", "nu", "f"))
        self.problem = TwoBodyProblem(
            copy,
            cell_tags,
            self.replica.facet_tags,
            bodies=tuple(Body(b.cells, E, nu, f) for b in problem.bodies),
            pair=problem.pair,
            supports=problem.supports,
            tractions=problem.tractions,
            name=problem.name,
        )
        # the copy's cell i is the gathered (rank-ordered) owned cell original[i]
        first = msh.comm.exscan(n_owned) if msh.comm.size > 1 else 0
        self._owned_cell = np.asarray(copy.topology.original_cell_index, dtype=np.int64) - (first or 0)
        self._n_owned = n_owned

    def serial_state(self, state: PairState | None) -> PairState | None:
        """A load step's state on the ranks (owned displacement DOFs) as the copy's."""
        if state is None:
            return None
        u = fem.Function(self.V)
        owned = self.V.dofmap.index_map.size_local * self.V.dofmap.index_map_bs
        u.x.array[:owned] = np.asarray(state.u, dtype=np.float64)[:owned]
        return PairState(self.replica.gather(u), state.anchor, state.interface)

    def distributed(self, result: TwoBodyHybridResult) -> TwoBodyHybridResult:
        """The copy's solution on the ranks: u in the distributed P1 space, the strip as owned cells, the state's
        u as the owned DOFs; profiles, forces and friction as they are (the same on every rank)."""
        if not np.array_equal(result.u.function_space.dofmap.list, self.replica.V.dofmap.list):
            raise RuntimeError("the serial copy's P1 space and the solution's differ in numbering")
        u = fem.Function(self.V, name="u")
        self.replica.scatter(result.u.x.array, u)
        cells = self._owned_cell[result.strip]
        strip = np.sort(cells[(cells >= 0) & (cells < self._n_owned)]).astype(np.int32)
        owned = self.V.dofmap.index_map.size_local * self.V.dofmap.index_map_bs
        state = None
        if result.state is not None:
            state = PairState(u.x.array[:owned].copy(), result.state.anchor, result.state.interface)
        return dataclasses.replace(result, u=u, strip=strip, state=state)
