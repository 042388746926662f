"""Closest points on triangle meshes through an AABB tree, and ray casting (NumPy, float64).

The tree splits the triangles at the median centroid along the box's longest axis until a
leaf holds at most `LEAF_SIZE` triangles. A query runs for all points at once: every point
starts at the root with an upper bound on its distance (its nearest mesh vertex, from a KD
tree), descends into the children whose box is not farther than that bound, and at the leaves
the exact point-triangle distances decide. Lengths are in the mesh's units (metres here).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial import cKDTree

LEAF_SIZE = 8


def closest_on_triangles(points: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Barycentric coordinates (N, 3) of the closest point on triangles tri (N, 3, 3) to
    points (N, 3).

    Region tests after Ericson, Real-Time Collision Detection, section 5.1.5, vectorised;
    degenerate triangles fall back to their nearest edge region.
    """
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    ab, ac, ap = b - a, c - a, points - a
    d1, d2 = _dot(ab, ap), _dot(ac, ap)
    bp, cp = points - b, points - c
    d3, d4 = _dot(ab, bp), _dot(ac, bp)
    d5, d6 = _dot(ab, cp), _dot(ac, cp)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = va + vb + vc
        v_in, w_in = vb / denom, vc / denom
        t_ab = d1 / (d1 - d3)
        t_ac = d2 / (d2 - d6)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
    bary = np.stack([1.0 - v_in - w_in, v_in, w_in], axis=1)
    # Later assignments win: edge regions override the interior, vertices override edges.
    cases = [
        ((va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0), [0 * t_bc, 1.0 - t_bc, t_bc]),
        ((vb <= 0) & (d2 >= 0) & (d6 <= 0), [1.0 - t_ac, 0 * t_ac, t_ac]),
        ((vc <= 0) & (d1 >= 0) & (d3 <= 0), [1.0 - t_ab, t_ab, 0 * t_ab]),
        ((d6 >= 0) & (d5 <= d6), [0.0, 0.0, 1.0]),
        ((d3 >= 0) & (d4 <= d3), [0.0, 1.0, 0.0]),
        ((d1 <= 0) & (d2 <= 0), [1.0, 0.0, 0.0]),
    ]
    for mask, columns in cases:
        value = np.stack([np.broadcast_to(np.asarray(x, dtype=np.float64), mask.shape)
                          for x in columns], axis=1)
        bary[mask] = value[mask]
    bad = ~np.isfinite(bary).all(axis=1)
    bary[bad] = [1.0, 0.0, 0.0]
    return np.clip(bary, 0.0, 1.0)


def _dot(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", u, v)


@dataclass
class AABBTree:
    """Static tree over a mesh's triangles. lo, hi: (K, 3) node boxes; left, right: (K,) child
    ids (-1 at leaves); start, count: each leaf's slice of `order` (triangle ids)."""

    vertices: np.ndarray
    faces: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    left: np.ndarray
    right: np.ndarray
    start: np.ndarray
    count: np.ndarray
    order: np.ndarray
    vertex_tree: cKDTree
    ring: np.ndarray
    tri_lo: np.ndarray
    tri_hi: np.ndarray
    normals: np.ndarray

    @classmethod
    def build(cls, vertices: np.ndarray, faces: np.ndarray) -> AABBTree:
        """Tree over `faces` (M, 3) of `vertices` (N, 3)."""
        vertices = np.asarray(vertices, dtype=np.float64)
        faces = np.asarray(faces, dtype=np.int64)
        tri = vertices[faces]
        tmin, tmax, cen = tri.min(axis=1), tri.max(axis=1), tri.mean(axis=1)
        nodes: list[list] = []  # lo, hi, left, right, start, count
        order = np.arange(len(faces))
        stack = [(0, len(faces), -1, 0)]  # (start, stop, parent, which child)
        while stack:
            s, e, parent, side = stack.pop()
            ids = order[s:e]
            node = len(nodes)
            nodes.append([tmin[ids].min(0), tmax[ids].max(0), -1, -1, s, e - s])
            if parent >= 0:
                nodes[parent][2 + side] = node
            if e - s <= LEAF_SIZE:
                continue
            axis = int(np.argmax(nodes[node][1] - nodes[node][0]))
            mid = (e - s) // 2
            part = np.argpartition(cen[ids, axis], mid)
            order[s:e] = ids[part]
            stack.append((s + mid, e, node, 1))
            stack.append((s, s + mid, node, 0))
        fields = list(zip(*nodes, strict=True))
        return cls(vertices, faces, np.array(fields[0]), np.array(fields[1]),
                   np.array(fields[2]), np.array(fields[3]), np.array(fields[4]),
                   np.array(fields[5]), order, cKDTree(vertices), _one_rings(len(vertices), faces),
                   tmin, tmax, _unit_normals(tri))

    def refit(self, vertices: np.ndarray) -> AABBTree:
        """This tree's split of the same faces, over the vertices moved to `vertices` (N, 3):
        every box recomputed from its triangles, leaves first, so queries stay exact; about a
        tenth of a new build's time for a hand mesh. The split suits poses near the one it
        was built for (a hand from frame to frame)."""
        vertices = np.asarray(vertices, dtype=np.float64)
        tri = vertices[self.faces]
        tmin, tmax = tri.min(axis=1), tri.max(axis=1)
        lo, hi = np.empty_like(self.lo), np.empty_like(self.hi)
        leaves = np.flatnonzero(self.left < 0)
        leaves = leaves[np.argsort(self.start[leaves])]  # their slices tile `order`
        lo[leaves] = np.minimum.reduceat(tmin[self.order], self.start[leaves])
        hi[leaves] = np.maximum.reduceat(tmax[self.order], self.start[leaves])
        # Children come after their parent (the build numbers nodes depth first).
        for node in np.flatnonzero(self.left >= 0)[::-1]:
            a, b = self.left[node], self.right[node]
            lo[node] = np.minimum(lo[a], lo[b])
            hi[node] = np.maximum(hi[a], hi[b])
        return replace(self, vertices=vertices, lo=lo, hi=hi, vertex_tree=cKDTree(vertices),
                       tri_lo=tmin, tri_hi=tmax, normals=_unit_normals(tri))

    def closest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Closest surface points of points (P, 3).

        Returns distance (P,), face id (P,) and barycentric coordinates (P, 3) on that face.
        """
        points = np.asarray(points, dtype=np.float64)
        bound = self._ring_bound(points) * (1.0 + 1e-9) + 1e-12
        pt = np.arange(len(points))
        node = np.zeros(len(points), dtype=np.int64)
        pt_parts: list[np.ndarray] = []
        face_parts: list[np.ndarray] = []
        while pt.size:
            rel = points[pt]
            gap = np.maximum(self.lo[node] - rel, 0) + np.maximum(rel - self.hi[node], 0)
            keep = (gap * gap).sum(1) <= bound[pt] ** 2
            pt, node = pt[keep], node[keep]
            leaf = self.left[node] < 0
            if leaf.any():
                lp, ln = pt[leaf], node[leaf]
                counts = self.count[ln]
                rep = np.repeat(lp, counts)
                offs = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
                pt_parts.append(rep)
                face_parts.append(self.order[np.repeat(self.start[ln], counts) + offs])
            inner = ~leaf
            pt = np.concatenate([pt[inner], pt[inner]])
            node = np.concatenate([self.left[node[inner]], self.right[node[inner]]])
        cand_pt, cand_face = np.concatenate(pt_parts), np.concatenate(face_parts)
        # Cheap lower bounds (the face's plane, the face's own box) discard most candidates
        # before the exact point-triangle distance.
        rel = points[cand_pt]
        corner = self.vertices[self.faces[cand_face, 0]]
        plane = np.abs(_dot(rel - corner, self.normals[cand_face]))
        gap = (np.maximum(self.tri_lo[cand_face] - rel, 0)
               + np.maximum(rel - self.tri_hi[cand_face], 0))
        lower = np.maximum(plane, np.sqrt((gap * gap).sum(1)))
        keep = lower <= bound[cand_pt]
        return self._best(points, cand_pt[keep], cand_face[keep])

    def _ring_bound(self, points: np.ndarray) -> np.ndarray:
        """(P,) an upper bound on each point's distance: the exact distance to the triangles
        around its nearest vertex, which is usually the answer and so prunes the tree hard."""
        _, nearest = self.vertex_tree.query(points)
        ring = self.ring[nearest]  # (P, R), -1 padded
        rows, cols = np.nonzero(ring >= 0)
        dist, _, _ = self._best(points, rows, ring[rows, cols])
        return dist

    def _best(self, points: np.ndarray, cand_pt: np.ndarray, cand_face: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The nearest of each point's candidate faces: (distance, face, barycentrics) (P,).

        cand_pt, cand_face: (C,) pairs of a point index and a face index to compare.
        """
        tri = self.vertices[self.faces[cand_face]]
        bary = closest_on_triangles(points[cand_pt], tri)
        near = np.einsum("ni,nij->nj", bary, tri)
        dist = np.sqrt(((points[cand_pt] - near) ** 2).sum(1))
        best = np.full(len(points), np.inf)
        np.minimum.at(best, cand_pt, dist)
        winner = np.flatnonzero(dist == best[cand_pt])
        # Ties (a point nearest to an edge or vertex shared by faces): keep one per point.
        first = np.full(len(points), -1)
        first[cand_pt[winner[::-1]]] = winner[::-1]
        pick = first[first >= 0] if (first >= 0).all() else first[np.unique(cand_pt)]
        return dist[pick], cand_face[pick], bary[pick]


def _unit_normals(tri: np.ndarray) -> np.ndarray:
    """(M, 3) unit normals of triangles (M, 3, 3); zero for degenerate ones (bound stays 0)."""
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    length = np.linalg.norm(normal, axis=1, keepdims=True)
    return np.where(length > 0, normal / np.where(length > 0, length, 1.0), 0.0)


def _one_rings(num_vertices: int, faces: np.ndarray) -> np.ndarray:
    """(N, R) ids of the faces around each vertex, padded with -1."""
    vert = faces.ravel()
    face = np.repeat(np.arange(len(faces)), 3)
    order = np.argsort(vert, kind="stable")
    vert, face = vert[order], face[order]
    counts = np.bincount(vert, minlength=num_vertices)
    ring = np.full((num_vertices, max(int(counts.max()), 1)), -1, dtype=np.int64)
    slot = np.arange(len(vert)) - np.repeat(np.cumsum(counts) - counts, counts)
    ring[vert, slot] = face
    return ring


def ray_hits(origin: np.ndarray, direction: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Distance along one ray (origin (3,), unit direction (3,)) to each triangle (M, 3, 3).

    Moller-Trumbore, both faces count; np.inf where the ray misses.
    """
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    p = np.cross(direction, e2)
    det = _dot(e1, p)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        s = origin - tri[:, 0]
        u = _dot(s, p) * inv
        q = np.cross(s, e1)
        v = q @ direction * inv
        t = _dot(e2, q) * inv
    # A hair of slack on the edges so that a ray through a vertex or an edge is not lost
    # between the triangles that share it.
    slack = 1e-9
    hit = (np.abs(det) > 1e-15) & (u >= -slack) & (v >= -slack) & (u + v <= 1 + slack) & (t > 0)
    return np.where(hit, t, np.inf)
