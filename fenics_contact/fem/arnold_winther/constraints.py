"""Essential stress conditions of the Arnold–Winther space on straight boundary edges, and the traction lifting.

σn·t = 0 (sliding) and σn = 0 (traction free) are imposed by dropping edge moments and restricting the
vertex values to the null space of the stacked vertex constraints (which also handles corners).  A
prescribed traction σn = t on some of the σn = 0 edges is carried by a *lifting* σ_t: a fixed stress whose
edge moments are those of t and whose vertex values solve the stacked constraints with right-hand side t
(least squares where the data of two edges meeting at a corner disagree); the stress is σ = P c + σ_t.
The split interface (σ_tt doubled at the vertices of γ) adds, at each γ vertex, the null space of
σ ↦ σn on the γ edges there and of the vertex's own constraints: one function where γ is straight, none where
it bends (the tractions on two edges of different normals fix all of σ(v)).
"""

from __future__ import annotations

import numpy as np

from fenics_contact.fem.arnold_winther.functionals import MOMENT_WEIGHTS, edge_frames, edge_points
from fenics_contact.fem.arnold_winther.topology import TriangleEntities

__all__ = ["EssentialConstraints"]


class EssentialConstraints:
    """Constraint rows, null spaces and kept edge moments of the constrained edges of all ranks.

    Attributes: ``vertex_constraints`` (stacked rows (k, 3) acting on σ(v) per constrained local vertex),
    ``null`` (orthonormal null-space rows per constrained vertex), ``keep_edge`` (n_e, 4) the kept edge
    moments, ``split_bases`` (the split-interface functions per γ vertex), ``incompatible_vertices`` (local
    vertices where the prescribed tractions of two edges disagree; set by ``lifting``).
    """

    def __init__(self, entities: TriangleEntities, comm, tangential, traction, prescribed) -> None:
        self.entities = entities
        self.comm = comm
        #: stacked essential constraint rows (k, 3) acting on the vertex value σ(v), per constrained local vertex
        self.vertex_constraints: dict[int, np.ndarray] = {}
        self._vertex_rhs: dict[int, np.ndarray] = {}
        self.split_bases: dict[int, np.ndarray] = {}
        #: local vertices where the prescribed tractions of two edges are incompatible (least-squares value used)
        self.incompatible_vertices: np.ndarray = np.zeros(0, dtype=np.int64)
        self._gather(tangential, traction, prescribed)

    def _gather(self, tangential, traction, prescribed) -> None:
        """Gather the constrained facets of all ranks; constraint rows, right-hand sides and kept edge moments.

        On each listed edge e (unit normal n, tangent t) the moments of σn·t
        (and of σn·n for traction-free edges) are dropped, and at its vertices
        the value σ(v) is restricted to the null space of the rows
        σ ↦ σn·t (resp. σ ↦ σn), stacked over all constrained edges at v (in the order
        kind, global facet number: the same on every rank).  The right-hand sides of the
        rows (zero, or the prescribed traction at v) are kept for the lifting.
        """
        ent = self.entities
        sets = [np.unique(np.asarray([] if f is None else f, dtype=np.int64)) for f in (tangential, traction)]
        for facets in sets:
            if facets.size and (facets.min() < 0 or facets.max() >= ent.num_edges):
                raise ValueError("Facet index out of range.")
        group_of = np.full(ent.num_edges, -1, dtype=np.int64)
        for k, (facets, _) in enumerate(prescribed or []):
            facets = np.asarray(facets, dtype=np.int64)
            if not np.all(np.isin(facets, sets[1])):
                raise ValueError("prescribed-traction facets must be among the zero_traction_facets")
            group_of[facets] = k
        self._tractions = [value for _, value in (prescribed or [])]
        # records: kind (0 tangential, 1 traction), facet gid, vertex gids, rows (2, 3), nrows, rhs (2 vertices, 2),
        # group
        recs = []
        for kind, facets in enumerate(sets):
            if facets.size == 0:
                continue
            start, end = ent.vx[ent.edge_start[facets]], ent.vx[ent.edge_end[facets]]
            _, wt = edge_frames(start, end)
            t = (end - start) / np.linalg.norm(end - start, axis=-1, keepdims=True)
            n0, n1 = t[:, 1], -t[:, 0]
            F = facets.size
            rows = np.zeros((F, 2, 3))
            rhs = np.zeros((F, 2, 2))
            if kind == 0:
                rows[:, 0] = wt
            else:
                rows[:, 0, 0], rows[:, 0, 1], rows[:, 1, 1], rows[:, 1, 2] = n0, n1, n0, n1
                outward = ent.outward_sign(facets, np.stack([n0, n1], axis=1))
                for i, e in enumerate(facets):
                    if group_of[e] < 0:
                        continue
                    x = np.zeros((3, 2))
                    x[:2] = ent.vx[ent.e2v[e]].T
                    val = np.asarray(self._tractions[group_of[e]](x), dtype=np.float64).reshape(2, 2)
                    rhs[i] = outward[i] * val.T  # σ n_e = ±t(v), n_e = ±(outward normal)
            recs.append(
                {
                    "kind": np.full(F, kind, dtype=np.int64),
                    "gid": ent.edge_gid[facets],
                    "v": ent.vertex_gid[ent.e2v[facets]],
                    "rows": rows,
                    "rhs": rhs,
                    "group": group_of[facets],
                }
            )
        keys = ("kind", "gid", "v", "rows", "rhs", "group")
        empty = {
            "kind": np.zeros(0, np.int64),
            "gid": np.zeros(0, np.int64),
            "v": np.zeros((0, 2), np.int64),
            "rows": np.zeros((0, 2, 3)),
            "rhs": np.zeros((0, 2, 2)),
            "group": np.zeros(0, np.int64),
        }
        local = {k: np.concatenate([r[k] for r in recs]) if recs else empty[k] for k in keys}
        if self.comm.size > 1:
            parts = self.comm.allgather(local)
            local = {k: np.concatenate([p[k] for p in parts]) for k in keys}
        _, first = np.unique(np.stack([local["kind"], local["gid"]], axis=1), axis=0, return_index=True)
        rec = {k: v[first] for k, v in local.items()}  # unique, sorted by (kind, gid)
        self._constrained = rec
        # kept edge moments of the local edges
        keep_edge = np.ones((ent.num_edges, 4), dtype=bool)
        for kind, dropped in ((0, [2, 3]), (1, [0, 1, 2, 3])):
            hit = np.isin(ent.edge_gid, rec["gid"][rec["kind"] == kind])
            keep_edge[np.ix_(hit, dropped)] = False
        self.keep_edge = keep_edge
        # stacked rows and right-hand sides at the local constrained vertices
        order = np.argsort(ent.vertex_gid, kind="stable")
        gids_sorted = ent.vertex_gid[order]
        rows_at: dict[int, list[np.ndarray]] = {}
        rhs_at: dict[int, list[np.ndarray]] = {}
        for i in range(rec["gid"].size):
            nrow = 1 if rec["kind"][i] == 0 else 2
            for side in range(2):
                g = rec["v"][i, side]
                pos = np.searchsorted(gids_sorted, g)
                if pos >= gids_sorted.size or gids_sorted[pos] != g:
                    continue  # the vertex is not on this rank
                v = int(order[pos])
                rows_at.setdefault(v, []).append(rec["rows"][i, :nrow])
                rhs_at.setdefault(v, []).append(rec["rhs"][i, side, :nrow])
        self.null: dict[int, np.ndarray] = {}
        for v in sorted(rows_at):
            stacked = np.vstack(rows_at[v])
            self.vertex_constraints[v] = stacked
            self._vertex_rhs[v] = np.concatenate(rhs_at[v])
            _, sv, vt = np.linalg.svd(stacked)
            null = vt[int(np.sum(sv > 1e-10 * sv.max())) :]  # (k, 3) orthonormal rows
            null[np.abs(null) < 1e-14] = 0.0
            self.null[v] = null

    def split_interface(self, facets) -> None:
        """Extra vertex functions of the split interface: null space of σ ↦ σn (γ) and the vertex's constraints."""
        ent = self.entities
        facets = np.unique(np.asarray(facets, dtype=np.int64))
        start, end = ent.vx[ent.edge_start[facets]], ent.vx[ent.edge_end[facets]]
        t = (end - start) / np.linalg.norm(end - start, axis=-1, keepdims=True) if facets.size else np.zeros((0, 2))
        local = {"gid": ent.edge_gid[facets], "v": ent.vertex_gid[ent.e2v[facets]], "t": t}
        if self.comm.size > 1:
            parts = self.comm.allgather(local)
            local = {k: np.concatenate([p[k] for p in parts]) for k in local}
        _, first = np.unique(local["gid"], return_index=True)
        order = np.argsort(ent.vertex_gid, kind="stable")
        gids_sorted = ent.vertex_gid[order]
        rows_at: dict[int, list[np.ndarray]] = {}
        for i in first:
            n0, n1 = local["t"][i, 1], -local["t"][i, 0]
            rows = np.array([[n0, n1, 0.0], [0.0, n0, n1]])
            for g in local["v"][i]:
                pos = np.searchsorted(gids_sorted, g)
                if pos < gids_sorted.size and gids_sorted[pos] == g:
                    rows_at.setdefault(int(order[pos]), []).append(rows)
        for v in sorted(rows_at):
            # the side-2 value z must also satisfy the essential conditions at v (a γ end on a
            # traction-free, traction or contact side): z in the null space of all rows
            rows = rows_at[v] + ([self.vertex_constraints[v]] if v in self.vertex_constraints else [])
            _, sv, vt = np.linalg.svd(np.vstack(rows))
            null = vt[int(np.sum(sv > 1e-10 * sv.max())) :]
            if null.shape[0]:
                self.split_bases[v] = null

    def lifting(self) -> np.ndarray:
        """Full local AW coefficients of the traction lifting: edge moments of ±t on the traction edges,
        vertex values by least squares on the stacked vertex constraints (min-norm: ⊥ the free part)."""
        ent = self.entities
        nv = ent.num_vertices
        d = np.zeros(ent.num_dofs_full)
        q = MOMENT_WEIGHTS  # (2, nq)
        rec = self._constrained
        for k, value in enumerate(self._tractions):
            gids = rec["gid"][(rec["kind"] == 1) & (rec["group"] == k)]
            facets = np.flatnonzero(np.isin(ent.edge_gid, gids))
            if facets.size == 0:
                continue
            start, end = ent.vx[ent.edge_start[facets]], ent.vx[ent.edge_end[facets]]
            tan = (end - start) / np.linalg.norm(end - start, axis=1, keepdims=True)
            nrm = np.stack([tan[:, 1], -tan[:, 0]], axis=1)
            sign = ent.outward_sign(facets, nrm)
            pts = edge_points(start, end)  # (F, nq, 2)
            x = np.zeros((3, pts.shape[0] * pts.shape[1]))
            x[:2] = pts.reshape(-1, 2).T
            t = np.asarray(value(x), dtype=np.float64).reshape(2, -1).T.reshape(pts.shape)  # (F, nq, 2)
            tn = sign[:, None] * np.einsum("fqi,fi->fq", t, nrm)  # σn_e·n_e
            tt = sign[:, None] * np.einsum("fqi,fi->fq", t, tan)  # σn_e·t_e
            moments = np.concatenate([tn @ q.T, tt @ q.T], axis=1)  # (F, 4)
            d[(3 * nv + 4 * facets[:, None] + np.arange(4)).ravel()] = moments.ravel()
        bad = []
        for v, rows in self.vertex_constraints.items():
            rhs = self._vertex_rhs[v]
            if not np.any(rhs):
                continue
            value, *_ = np.linalg.lstsq(rows, rhs, rcond=None)
            if np.linalg.norm(rows @ value - rhs) > 1e-10 * max(np.linalg.norm(rhs), 1e-300):
                bad.append(v)
            d[3 * v : 3 * v + 3] = value
        self.incompatible_vertices = np.asarray(bad, dtype=np.int64)
        return d
