"""Where the contact boundary Γ_C ends openly and where the interface γ bends, on a triangle mesh
(``problem.validation``; a tetrahedral mesh has neither checked)."""

import numpy as np

from fenics_contact.problem.validation_rules import GAMMA, GAMMA_C
from fenics_contact.problem.validation_triangles import Edges, MeshDescription, describe_contact_mesh

__all__ = ["OPEN_END_ANGLE", "BEND", "open_ends", "contact_open_ends", "interface_bends", "interface_bends_of"]

#: Γ_C "ends openly" where the boundary goes on within this angle of Γ_C's own direction (degrees)
OPEN_END_ANGLE = 30.0


def open_ends(desc: MeshDescription, group: str = GAMMA_C, angle: float = OPEN_END_ANGLE) -> np.ndarray:
    """(k, 3): x, y of each end point of the facet group where the boundary continues nearly straight (within
    ``angle``), and the length of the group's facet that ends there.

    An end of Γ_C at a corner of the body (the bar's wall side) is a true end of the possible contact zone; an
    end where the boundary goes on straight (Γ_C a part of one side, as in a Hertz block) is not: a contact zone
    that reaches it is cut short by the tags, not by the mechanics.
    """
    seg = np.asarray(desc.facets.get(group, np.zeros((0, 2), np.int64)), dtype=np.int64).reshape(-1, 2)
    pts = np.asarray(desc.points, dtype=np.float64)
    if seg.shape[0] == 0:
        return np.zeros((0, 3))
    degree = np.bincount(seg.ravel(), minlength=pts.shape[0])
    edges = Edges(desc)
    outer = edges.nodes[edges.exterior]
    others = outer[~np.isin(edges.keys(outer), edges.keys(seg))]  # exterior edges not in the group
    cos_max = np.cos(np.radians(angle))
    found = []
    for e in np.flatnonzero(degree == 1):
        own = seg[np.any(seg == e, axis=1)][0]
        d1 = pts[e] - pts[own[0] if own[1] == e else own[1]]  # along Γ_C, out of its end
        for q in others[np.any(others == e, axis=1)]:
            d2 = pts[q[0] if q[1] == e else q[1]] - pts[e]
            if d1 @ d2 > cos_max * np.linalg.norm(d1) * np.linalg.norm(d2):
                found.append([pts[e][0], pts[e][1], np.linalg.norm(d1)])
                break
    return np.array(found, dtype=np.float64).reshape(-1, 3)


def contact_open_ends(cm) -> np.ndarray:
    """``open_ends`` of Γ_C on every rank (collective: the mesh is described on rank 0); none on a tetrahedral
    mesh (the ends of a contact curve: a contact surface is not checked)."""
    if cm.mesh.topology.dim == 3:
        return np.zeros((0, 3))
    desc = describe_contact_mesh(cm, [GAMMA_C])
    ends = open_ends(desc) if cm.comm.rank == 0 else None
    return cm.comm.bcast(ends, root=0)


#: sin of the angle between two γ facets at a common vertex above which γ bends there
BEND = 1e-8


def interface_bends(desc: MeshDescription) -> np.ndarray:
    """(k, 2): the vertices where the interface γ bends (two γ facets meet at an angle) or branches."""
    seg = np.asarray(desc.facets.get(GAMMA, np.zeros((0, 2), np.int64)), dtype=np.int64).reshape(-1, 2)
    pts = np.asarray(desc.points, dtype=np.float64)
    if seg.shape[0] == 0:
        return np.zeros((0, 2))
    degree = np.bincount(seg.ravel(), minlength=pts.shape[0])
    found = [pts[v, :2] for v in np.flatnonzero(degree > 2)]
    d = pts[seg[:, 1], :2] - pts[seg[:, 0], :2]
    d /= np.linalg.norm(d, axis=1)[:, None]
    for v in np.flatnonzero(degree == 2):
        a, b = np.flatnonzero(np.any(seg == v, axis=1))
        if abs(d[a, 0] * d[b, 1] - d[a, 1] * d[b, 0]) > BEND:
            found.append(pts[v, :2])
    return np.array(found, dtype=np.float64).reshape(-1, 2)


def interface_bends_of(cm) -> np.ndarray:
    """``interface_bends`` of γ on every rank (collective: the mesh is described on rank 0); none on a tetrahedral
    mesh (the bends of an interface curve, which the mixed methods need to know: they are planar)."""
    if cm.mesh.topology.dim == 3:
        return np.zeros((0, 2))
    desc = describe_contact_mesh(cm, [GAMMA])
    bends = interface_bends(desc) if cm.comm.rank == 0 else None
    return cm.comm.bcast(bends, root=0)
