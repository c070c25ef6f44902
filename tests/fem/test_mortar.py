"""The contact geometry of two bodies (``fem.mortar``): closest points on segments and triangles, and the
coupling rows of the contact quadrature."""

import numpy as np
import pytest
from mpi4py import MPI

from fenics_contact.fem.mortar import Surface, contact_quadrature, project

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="serial geometry")


def _surface(coords: np.ndarray, blocks: np.ndarray, outward: np.ndarray) -> Surface:
    """A surface of the given facets with the normals pointing to the side of ``outward``."""
    if coords.shape[2] == 2:
        t = coords[:, 1] - coords[:, 0]
        n = np.stack([t[:, 1], -t[:, 0]], axis=1)
        measures = np.linalg.norm(t, axis=1)
    else:
        n = np.cross(coords[:, 1] - coords[:, 0], coords[:, 2] - coords[:, 0])
        measures = 0.5 * np.linalg.norm(n, axis=1)
    n /= np.linalg.norm(n, axis=1)[:, None]
    n *= np.sign(n @ outward)[:, None]
    return Surface(coords, blocks, n, measures)


def test_closest_points_on_a_bent_triangulated_surface_beat_a_fine_sampling():
    """Random points above a roof of four triangles: the projection is never farther than the best of a dense
    sampling of the triangles, and at most the sampling's resolution nearer."""
    rng = np.random.default_rng(7)
    x = np.array([[0, 0, 0], [1, 0, 0.3], [2, 0, 0], [0, 1, 0], [1, 1, 0.3], [2, 1, 0]], dtype=float)
    tris = np.array([[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4]])
    surf = _surface(x[tris], tris, np.array([0.0, 0.0, 1.0]))
    points = np.column_stack([rng.uniform(-0.3, 2.3, 100), rng.uniform(-0.3, 1.3, 100), rng.uniform(0.0, 0.6, 100)])
    proj = project(points, surf)
    closest = np.einsum("nk,nkd->nd", proj.bary, surf.coords[proj.facet])
    mine = np.linalg.norm(points - closest, axis=1)
    s, t = np.meshgrid(np.linspace(0, 1, 101), np.linspace(0, 1, 101))
    keep = s + t <= 1
    lam = np.column_stack([1 - s[keep] - t[keep], s[keep], t[keep]])
    samples = np.concatenate([lam @ x[tri] for tri in tris])
    brute = np.min(np.linalg.norm(points[:, None, :] - samples[None, :, :], axis=2), axis=1)
    assert np.all(mine <= brute + 1e-12)
    assert np.all(mine >= brute - 2.0 / 100)
    assert np.allclose(proj.bary.sum(axis=1), 1.0) and np.all(proj.bary >= 0.0)


def test_points_beyond_the_rim_of_the_master_do_not_face_it():
    """A flat master segment (0, 1) × {0}: points above it face it with the gap their height; points beyond its
    ends do not."""
    x = np.array([[0.0, 0.0], [0.5, 0.0], [1.0, 0.0]])
    segs = np.array([[0, 1], [1, 2]])
    master = _surface(x[segs], segs, np.array([0.0, 1.0]))
    points = np.array([[0.2, 0.1], [0.7, 0.05], [1.3, 0.1], [-0.2, 0.0]])
    proj = project(points, master)
    assert proj.found.tolist() == [True, True, False, False]
    assert np.allclose(proj.gap[:2], [0.1, 0.05]) and np.allclose(proj.nu[:2], [0.0, -1.0])


@pytest.mark.parametrize("nodal", [True, False])
def test_coupling_rows_sum_to_the_normal_on_each_side(nodal):
    """Each row of B holds ν·N_i on the slave and −ν·M_j on the master: per side the coefficients sum to ν
    (partitions of unity), so the contact forces on the two bodies are equal and opposite."""
    xs = np.column_stack([np.linspace(0, 1, 8), np.full(8, 0.01)])  # slave: 7 segments above the master
    xm = np.column_stack([np.linspace(0, 1, 11), np.zeros(11)])  # master: 10 segments
    slave = _surface(xs[np.c_[0:7, 1:8]], np.c_[0:7, 1:8], np.array([0.0, -1.0]))
    master = _surface(xm[np.c_[0:10, 1:11]], 8 + np.c_[0:10, 1:11], np.array([0.0, 1.0]))
    Q = contact_quadrature(slave, master, 2 * 19, 2, 3, nodal=nodal)
    B = Q.B.toarray().reshape(Q.B.shape[0], 19, 2)
    assert np.allclose(B[:, :8].sum(axis=1), Q.nu) and np.allclose(B[:, 8:].sum(axis=1), -Q.nu)
    assert np.allclose(Q.gap, 0.01)
    assert Q.weights.sum() == pytest.approx(1.0)  # the slave's length
    if nodal:
        assert Q.nodes.tolist() == list(range(8))
    else:  # 7 + 10 − 1 segments after the cuts at the master vertices, 2 Gauss points each
        assert Q.B.shape[0] == 2 * 16


@pytest.mark.parametrize("nodal", [True, False])
def test_relative_rows_are_the_jump_whose_normal_part_is_the_penetration(nodal):
    """The rows of ``relative`` (one per point and component) hold N_i on the slave's and −M_j on the master's
    DOFs of their own component: per side they sum to ±1 (a rigid translation has no jump, the friction forces
    on the two bodies are equal and opposite), and on a flat, inclined pair ν·(relative u) = B u for any u."""
    angle = 0.3
    rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    xs = np.column_stack([np.linspace(0, 1, 8), np.full(8, 0.01)]) @ rot.T
    xm = np.column_stack([np.linspace(-0.1, 1.1, 11), np.zeros(11)]) @ rot.T
    slave = _surface(xs[np.c_[0:7, 1:8]], np.c_[0:7, 1:8], rot @ np.array([0.0, -1.0]))
    master = _surface(xm[np.c_[0:10, 1:11]], 8 + np.c_[0:10, 1:11], rot @ np.array([0.0, 1.0]))
    Q = contact_quadrature(slave, master, 2 * 19, 2, 3, nodal=nodal)
    R = Q.relative.toarray().reshape(-1, 2, 19, 2)  # (point, component, node, component)
    eye = np.eye(2)[None]
    assert np.allclose(R[:, :, :8].sum(axis=2), eye) and np.allclose(R[:, :, 8:].sum(axis=2), -eye)
    u = np.random.default_rng(3).standard_normal(2 * 19)
    jump = (Q.relative @ u).reshape(-1, 2)
    assert np.allclose(np.sum(jump * Q.nu, axis=1), Q.B @ u, rtol=0.0, atol=1e-13)
    assert np.allclose(Q.relative @ np.tile([0.7, -0.2], 19), 0.0, atol=1e-14)  # a rigid translation
