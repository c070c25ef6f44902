"""Convex polygons clipped by half-planes, batched: the 3D segment-to-segment contact quadrature (``fem.mortar``).

A slave triangle is described in its own affine coordinates ξ = (ξ₁, ξ₂) (x = x₀ + ξ₁(x₁ − x₀) + ξ₂(x₂ − x₀),
the reference triangle ξ ≥ 0, ξ₁ + ξ₂ ≤ 1); the master triangles near it are projected onto its plane along
its normal and written in the same coordinates.  ``partition`` cuts each slave triangle into convex pieces,
each inside one projected master triangle or outside all of them (Sutherland–Hodgman, one half-plane at a
time, on padded arrays of polygons: all slave triangles at once), and ``fan_rule`` puts a Gauss rule on a fan
triangulation of every piece.  On a piece the slave and master P1 traces are both affine in ξ (a flat pair),
so the contact integrals of polynomials are exact.
"""

import basix
import numpy as np

__all__ = ["clip", "areas", "partition", "intersections", "fan_rule"]

#: pieces of a smaller area (reference coordinates, the slave triangle has ½) are dropped: round-off slivers
_SLIVER = 1e-14


def clip(poly: np.ndarray, count: np.ndarray, normal: np.ndarray, offset: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The convex polygons (N, M, 2) with ``count`` (N,) vertices each, cut to the half-planes
    normal·ξ + offset ≥ 0 (normal (N, 2), offset (N,)): (polygons (N, M', 2) padded with their first vertex,
    vertex counts)."""
    n, m = poly.shape[:2]
    idx = np.arange(m)
    real = idx[None, :] < count[:, None]
    nxt = np.where(idx[None, :] + 1 < count[:, None], idx[None, :] + 1, 0)
    after = np.take_along_axis(poly, nxt[..., None], axis=1)
    d0 = np.einsum("nmd,nd->nm", poly, normal) + offset[:, None]
    d1 = np.take_along_axis(d0, nxt, axis=1)
    inside0, inside1 = d0 >= 0.0, d1 >= 0.0
    cross = real & (inside0 != inside1)
    t = np.where(cross, d0 / np.where(cross, d0 - d1, 1.0), 0.0)
    hit = poly + t[..., None] * (after - poly)
    slots = np.stack([poly, hit], axis=2).reshape(n, 2 * m, 2)  # vertex i, then the crossing of edge (i, i + 1)
    keep = np.stack([real & inside0, cross], axis=2).reshape(n, 2 * m)
    new_count = keep.sum(axis=1)
    order = np.argsort(~keep, axis=1, kind="stable")
    width = max(int(new_count.max(initial=0)), 1)
    out = np.take_along_axis(slots, order[:, :width, None], axis=1)
    pad = np.arange(width)[None, :] >= new_count[:, None]
    out = np.where(pad[..., None], out[:, :1], out)
    return out, new_count


def areas(poly: np.ndarray) -> np.ndarray:
    """Signed areas of polygons padded with their first vertex (shoelace)."""
    x, y = poly[..., 0], poly[..., 1]
    return 0.5 * np.sum(x * np.roll(y, -1, axis=1) - np.roll(x, -1, axis=1) * y, axis=1)


def _pad(poly: np.ndarray, width: int) -> np.ndarray:
    if poly.shape[1] == width:
        return poly
    return np.concatenate([poly, np.repeat(poly[:, :1], width - poly.shape[1], axis=1)], axis=1)


def _join(parts: list[tuple[np.ndarray, ...]]) -> tuple[np.ndarray, ...]:
    width = max(p[0].shape[1] for p in parts)
    return (np.concatenate([_pad(p[0], width) for p in parts]),) + tuple(
        np.concatenate([p[i] for p in parts]) for i in range(1, len(parts[0]))
    )


def _half_planes(tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The three inner half-planes of triangles (N, 3, 2) of either orientation: normals (N, 3, 2), offsets (N, 3)."""
    edge = np.roll(tri, -1, axis=1) - tri
    normal = np.stack([-edge[..., 1], edge[..., 0]], axis=2)  # left of the edge: inside a counter-clockwise triangle
    normal *= np.sign(areas(tri))[:, None, None]
    return normal, -np.einsum("ned,ned->ne", normal, tri)


def partition(masters: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The reference slave triangle of each of S slaves cut by its K projected master triangles (S, K, 3, 2)
    (NaN: no master; the masters of one slave must not overlap): the pieces (P, M, 2) padded with their first
    vertex, their vertex counts, owners (the slave, (P,)) and master slot (0 … K − 1, or −1: outside every master)."""
    s, k = masters.shape[:2]
    ref = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    poly, count, owner = np.tile(ref, (s, 1, 1)), np.full(s, 3), np.arange(s)
    done = []
    for j in range(k):
        tri = masters[owner, j]
        live = np.all(np.isfinite(tri), axis=(1, 2))
        live[live] = np.abs(areas(tri[live])) > _SLIVER
        parts = [(poly[~live], count[~live], owner[~live])]
        inside, n_in, own = poly[live], count[live], owner[live]
        normal, offset = _half_planes(tri[live])
        for e in range(3):
            out, n_out = clip(inside, n_in, -normal[:, e], -offset[:, e])
            parts.append((out, n_out, own))
            inside, n_in = clip(inside, n_in, normal[:, e], offset[:, e])
        done.append((inside, n_in, own, np.full(own.size, j)))
        poly, count, owner = _join(parts)
        big = (count >= 3) & (np.abs(areas(poly)) > _SLIVER)
        poly, count, owner = poly[big], count[big], owner[big]
    done.append((poly, count, owner, np.full(owner.size, -1)))
    poly, count, owner, slot = _join(done)
    big = (count >= 3) & (np.abs(areas(poly)) > _SLIVER)
    return poly[big], count[big], owner[big], slot[big]


def intersections(masters: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The pieces of ``partition`` (same arguments and results), computed as the intersections of each reference
    slave triangle with each of its projected masters (all pairs at once) where these cover the triangle
    exactly once (their areas sum to ½), by ``partition`` for the other slaves (a master's rim, overlaps)."""
    s, k = masters.shape[:2]
    tri = masters.reshape(s * k, 3, 2)
    live = np.all(np.isfinite(tri), axis=(1, 2))
    live[live] = np.abs(areas(tri[live])) > _SLIVER
    pair = np.flatnonzero(live)
    ref = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    poly, count = np.tile(ref, (pair.size, 1, 1)), np.full(pair.size, 3)
    normal, offset = _half_planes(tri[pair])
    for e in range(3):
        poly, count = clip(poly, count, normal[:, e], offset[:, e])
    area = np.where(count >= 3, np.abs(areas(poly)), 0.0)
    owner, slot = pair // k, pair % k
    covered = np.bincount(owner, area, minlength=s)
    exact = np.abs(covered - 0.5) <= 1e-12
    keep = exact[owner] & (area > _SLIVER)
    parts = [(poly[keep], count[keep], owner[keep], slot[keep])]
    rest = np.flatnonzero(~exact)
    if rest.size:
        r_poly, r_count, r_owner, r_slot = partition(masters[rest])
        parts.append((r_poly, r_count, rest[r_owner], r_slot))
    return _join(parts)


def fan_rule(poly: np.ndarray, degree: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A Gauss rule of ``degree`` on the fan triangles (v₀, vᵢ, vᵢ₊₁) of convex polygons (P, M, 2) padded with their
    first vertex: (piece index, points ξ (n, 2), weights in reference area, summing to each piece's area)."""
    ref, ref_w = basix.make_quadrature(basix.CellType.triangle, degree)
    a, b, c = poly[:, :1], poly[:, 1:-1], poly[:, 2:]
    e1, e2 = b - a, c - a
    det = np.abs(e1[..., 0] * e2[..., 1] - e1[..., 1] * e2[..., 0])  # (P, M − 2): twice the fan triangles' areas
    piece, tri = np.nonzero(det > 0.0)
    pts = (
        a[piece, 0][:, None, :]
        + ref[None, :, :1] * e1[piece, tri][:, None]
        + ref[None, :, 1:] * e2[piece, tri][:, None]
    )
    weights = det[piece, tri][:, None] * ref_w[None, :]
    nq = ref.shape[0]
    return np.repeat(piece, nq), pts.reshape(-1, 2), weights.ravel()
