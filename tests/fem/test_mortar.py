"""The contact geometry of two bodies (``fem.mortar``): closest points on segments and triangles, and the
coupling rows of the contact quadrature."""

import numpy as np
import pytest
from mpi4py import MPI

from fenics_contact.fem import clipping
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


def _grid(n: int, z: float, rng: np.random.Generator, box=((0.0, 1.0), (0.0, 1.0))) -> tuple[np.ndarray, np.ndarray]:
    """An n × n grid of the box at height z, its inner vertices jittered by 0.3 cells, two triangles per square."""
    (x0, x1), (y0, y1) = box
    X, Y = np.meshgrid(np.linspace(x0, x1, n + 1), np.linspace(y0, y1, n + 1))
    x = np.column_stack([X.ravel(), Y.ravel(), np.full(X.size, z)])
    inner = (X.ravel() > x0) & (X.ravel() < x1) & (Y.ravel() > y0) & (Y.ravel() < y1)
    x[inner, :2] += 0.3 * rng.uniform(-1.0, 1.0, (inner.sum(), 2)) * [(x1 - x0) / n, (y1 - y0) / n]
    a = (np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]).ravel()
    tris = np.concatenate([np.c_[a, a + 1, a + n + 2], np.c_[a, a + n + 2, a + n + 1]])
    return x, tris


def test_clipping_cuts_a_triangle_into_pieces_of_one_master_each_or_of_none():
    """The reference triangle cut by a jittered triangulation of (−1, 0.4) × (−1, 2) (either orientation): the
    pieces tile it (areas sum to ½), each lies in its master triangle, and those of no master fill ξ₁ > 0.4
    (area 0.18); ``intersections`` gives the same pieces."""
    rng = np.random.default_rng(11)
    x, tris = _grid(6, 0.0, rng, box=((-1.0, 0.4), (-1.0, 2.0)))
    masters = x[tris][:, :, :2]
    masters[::2] = masters[::2, ::-1]  # half of them clockwise
    for pieces in (clipping.partition(masters[None]), clipping.intersections(masters[None])):
        poly, count, owner, slot = pieces
        area = np.abs(clipping.areas(poly))
        assert np.all(owner == 0) and np.all(count >= 3)
        assert area.sum() == pytest.approx(0.5, abs=1e-14)
        assert area[slot < 0].sum() == pytest.approx(0.5 * 0.6**2, abs=1e-14)
        assert np.all(poly[slot < 0][..., 0] >= 0.4 - 1e-14)
        for piece, j in zip(poly[slot >= 0], slot[slot >= 0]):
            tri = masters[j]
            for e in range(3):  # every vertex on the inner side of every edge of its master
                t, n = tri[(e + 1) % 3] - tri[e], piece - tri[e]
                side = (t[0] * n[:, 1] - t[1] * n[:, 0]) * np.sign(clipping.areas(tri[None]))[0]
                assert np.all(side >= -1e-14)


@pytest.mark.parametrize("sizes", [(3, 4), (7, 5)])
def test_clipped_quadrature_integrates_p1_traces_exactly_in_3d(sizes):
    """Two jittered non-matching triangulations of the unit square 0.01 apart, random P1 values on both: the
    3D segment-to-segment rule integrates the penetration of any P1 field exactly, ∫ s = Σ_T |T| mean(s) per side
    (the traces are affine on each piece), and the rows of B sum to ±ν per side."""
    rng = np.random.default_rng(5)
    xs, ts = _grid(sizes[0], 0.01, rng)
    xm, tm = _grid(sizes[1], 0.0, rng)
    ns, nm = xs.shape[0], xm.shape[0]
    slave = _surface(xs[ts], ts, np.array([0.0, 0.0, -1.0]))
    master = _surface(xm[tm], ns + tm, np.array([0.0, 0.0, 1.0]))
    u = rng.standard_normal(3 * (ns + nm))
    uz = u[2::3]
    exact = -np.sum(slave.measures * uz[ts].mean(axis=1)) + np.sum(master.measures * uz[ns + tm].mean(axis=1))
    for nodal in (False, True):
        Q = contact_quadrature(slave, master, 3 * (ns + nm), 3, 2, nodal=nodal)
        assert Q.weights.sum() == pytest.approx(1.0, abs=1e-14)
        assert np.allclose(Q.nu, [0.0, 0.0, -1.0]) and np.allclose(Q.gap, 0.01)
        assert np.sum(Q.weights * (Q.B @ u)) == pytest.approx(exact, abs=1e-13)
        B = Q.B.toarray().reshape(Q.B.shape[0], ns + nm, 3)
        assert np.allclose(B[:, :ns].sum(axis=1), Q.nu) and np.allclose(B[:, ns:].sum(axis=1), -Q.nu)


@pytest.mark.parametrize("dim", [2, 3])
def test_dual_nodal_gaps_are_the_penetration_at_the_nodes(dim):
    """Jittered non-matching surfaces 0.01 apart, the master not under the slave's first 0.15, different linear
    displacements on the two sides (a penetration s linear along the surface): with the dual basis the nodal gap
    s̃_p is s at the node itself wherever the node's facets wholly face the master (∫ ψ_p N_q = δ_pq ∫ N_p), the
    standard basis averages s over N_p (off on the jittered nodes); a uniform s is exact on every node with
    either basis (the patch test), and the nodal weights are ∫ N_p ds over the facets facing the master."""
    rng = np.random.default_rng(2)
    if dim == 2:
        xs = np.column_stack([np.linspace(0, 1, 10), np.full(10, 0.01)])
        xs[1:-1, 0] += 0.3 * rng.uniform(-1.0, 1.0, 8) / 9
        xm = np.column_stack([np.linspace(0.15, 1.0, 13), np.zeros(13)])
        ts, tm = np.c_[0:9, 1:10], np.c_[0:12, 1:13]
    else:
        xs, ts = _grid(5, 0.01, rng)
        xm, tm = _grid(6, 0.0, rng, box=((0.15, 1.0), (0.0, 1.0)))
    ns, nm = xs.shape[0], xm.shape[0]
    up = np.eye(dim)[-1]
    slave = _surface(xs[ts], ts, -up)
    master = _surface(xm[tm], ns + tm, up)
    full = np.ones(ns, dtype=bool)  # the nodes whose slave facets lie wholly over the master
    full[ts[np.any(xs[ts][..., 0] < 0.15 - 1e-12, axis=1)]] = False
    A_s, A_m = rng.standard_normal((dim, dim)), rng.standard_normal((dim, dim))
    u = np.concatenate([(xs @ A_s.T).ravel(), (xm @ A_m.T).ravel()])
    x = xs[:, :-1]  # s(x) = (u_s(x) − u_m(x))·ν − g on the flat pair, ν = −e_up
    s_exact = -(xs @ A_s.T)[:, -1] + (np.column_stack([x, np.zeros(ns)]) @ A_m.T)[:, -1] - 0.01
    for basis in ("dual", "standard"):
        Q = contact_quadrature(slave, master, dim * (ns + nm), dim, 2, basis=basis)
        s_nodes = Q.B @ u - Q.gap
        on = full[Q.nodes]
        off = np.max(np.abs(s_nodes[on] - s_exact[Q.nodes][on]))
        if basis == "dual":
            assert off < 1e-13
        else:
            assert off > 1e-4
        translation = np.concatenate([np.tile(-0.02 * up, ns), np.zeros(dim * nm)])
        assert np.allclose(Q.B @ translation - Q.gap, 0.01, rtol=0.0, atol=1e-15)
        assert np.allclose(Q.weights[on], _hat_integrals(slave)[Q.nodes][on], rtol=1e-13)


def _hat_integrals(surf: Surface) -> np.ndarray:
    """∫ N_p ds of each vertex over its facets."""
    k = surf.blocks.shape[1]
    out = np.zeros(surf.blocks.max() + 1)
    np.add.at(out, surf.blocks.ravel(), np.repeat(surf.measures / k, k))
    return out


def test_a_hinted_facet_gives_the_closest_point_on_a_convex_master():
    """Points above a convex roof of four triangles, each with a random facet as hint: where the orthogonal
    projection lies in the hinted facet it is the closest point (its plane supports the roof), elsewhere the
    search runs: the distances and gaps are those of the search without hints."""
    rng = np.random.default_rng(2)
    x = np.array([[0, 0, 0], [1, 0, 0.3], [2, 0, 0], [0, 1, 0], [1, 1, 0.3], [2, 1, 0]], dtype=float)
    tris = np.array([[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4]])
    surf = _surface(x[tris], tris, np.array([0.0, 0.0, 1.0]))
    points = np.column_stack([rng.uniform(-0.3, 2.3, 200), rng.uniform(-0.3, 1.3, 200), rng.uniform(0.35, 0.8, 200)])
    plain = project(points, surf)
    hinted = project(points, surf, hint=rng.integers(-1, 4, 200))
    d_plain = np.linalg.norm(points - np.einsum("nk,nkd->nd", plain.bary, surf.coords[plain.facet]), axis=1)
    d_hint = np.linalg.norm(points - np.einsum("nk,nkd->nd", hinted.bary, surf.coords[hinted.facet]), axis=1)
    assert np.allclose(d_hint, d_plain, rtol=0.0, atol=1e-12)
    inside = plain.found & hinted.found
    assert np.allclose(hinted.gap[inside], plain.gap[inside], rtol=0.0, atol=1e-12)
    assert np.array_equal(hinted.found, plain.found)
