"""The geometry kernel: closed primitives (boxes, frusta, ellipsoids, extrusions of 2D profiles, arches,
stairs) as vertices, faces, UVs in metres and normals."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass
class _Geom:
    v: np.ndarray  # (n, 3) positions
    f: np.ndarray  # (m, 3) int64 faces, counter-clockwise seen from outside
    uv: np.ndarray  # (n, 2) texture coordinates in metres
    n: np.ndarray  # (n, 3) unit normals
    solid: np.ndarray | None = None  # (m,) id of the closed primitive each face belongs to

    def __post_init__(self) -> None:
        if self.solid is None:
            self.solid = np.zeros(len(self.f), dtype=np.int64)


def _cat(geoms: list[_Geom], one_solid: bool = False) -> _Geom:
    """Concatenate; ``one_solid`` when the pieces close one primitive (sides + caps)."""
    offs = np.cumsum([0] + [len(g.v) for g in geoms[:-1]])
    if one_solid:
        solid = np.zeros(sum(len(g.f) for g in geoms), dtype=np.int64)
    else:
        ids, nxt = [], 0
        for g in geoms:
            ids.append(g.solid + nxt)
            nxt += int(g.solid.max()) + 1 if len(g.solid) else 0
        solid = np.concatenate(ids)
    return _Geom(
        np.concatenate([g.v for g in geoms]),
        np.concatenate([g.f + o for g, o in zip(geoms, offs)]),
        np.concatenate([g.uv for g in geoms]),
        np.concatenate([g.n for g in geoms]),
        solid,
    )


def _xf(g: _Geom, A: np.ndarray | None = None, t=(0.0, 0.0, 0.0)) -> _Geom:
    """Affine transform ``x -> A x + t`` (det A > 0); normals by the inverse transpose."""
    A = np.eye(3) if A is None else np.asarray(A, dtype=np.float64)
    n = g.n @ np.linalg.inv(A)  # == (inv(A)^T n^T)^T
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return _Geom(g.v @ A.T + np.asarray(t, dtype=np.float64), g.f.copy(), g.uv.copy(), n, g.solid.copy())


def _ry(a: float) -> np.ndarray:
    """Rotation about +Y by ``a`` radians (takes +z towards +x)."""
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _box(lo, hi) -> _Geom:
    """Axis-aligned box, 4 vertices per face (flat normals)."""
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    if np.any(hi - lo <= 1e-9):
        raise ValueError(f"box needs hi > lo on every axis, got lo={lo}, hi={hi}")
    quad = np.array([[0, 0], [1, 0], [1, 1], [0, 1]])
    vs, uvs, ns = [], [], []
    for a in range(3):
        b, c = (a + 1) % 3, (a + 2) % 3  # (a, b, c) cyclic: e_b x e_c = e_a
        for s in (-1, 1):
            q = quad if s > 0 else quad[::-1]
            p = np.empty((4, 3))
            p[:, a] = hi[a] if s > 0 else lo[a]
            p[:, b] = np.where(q[:, 0] == 1, hi[b], lo[b])
            p[:, c] = np.where(q[:, 1] == 1, hi[c], lo[c])
            if a == 1:
                uv = p[:, [0, 2]]
            else:  # walls: u along the face, v = -height (texture top is up)
                uv = np.stack([p[:, 2 if a == 0 else 0], -p[:, 1]], axis=1)
            nrm = np.zeros((4, 3))
            nrm[:, a] = s
            vs.append(p)
            uvs.append(uv)
            ns.append(nrm)
    f = np.array([[0, 1, 2], [0, 2, 3]])
    faces = np.concatenate([f + 4 * k for k in range(6)])
    return _Geom(np.concatenate(vs), faces, np.concatenate(uvs), np.concatenate(ns))


def _frustum(r0: float, r1: float, y0: float, y1: float, seg: int, smooth: bool = True,
             phase: float = 0.0, caps: bool = True) -> _Geom:
    """Cylinder / cone frustum around the Y axis: radius r0 at y0, r1 (>= 0) at y1.

    ``smooth`` gives analytic vertex normals (round objects); otherwise every side
    face has its own flat normal (prisms, pyramids). ``phase`` rotates the vertices.
    """
    if not (r0 > 0 and r1 >= 0 and y1 > y0 and seg >= 3):
        raise ValueError(f"bad frustum r0={r0}, r1={r1}, y0={y0}, y1={y1}, seg={seg}")
    h = y1 - y0
    th = phase + 2.0 * np.pi * np.arange(seg + 1) / seg
    rm = 0.5 * (r0 + r1)

    def ring(r, y, t):
        return np.stack([r * np.sin(t), np.full_like(t, y), r * np.cos(t)], axis=1)

    def slant(t):
        n = np.stack([h * np.sin(t), np.full_like(t, r0 - r1), h * np.cos(t)], axis=1)
        return n / np.linalg.norm(n, axis=1, keepdims=True)

    parts: list[_Geom] = []
    j = np.arange(seg)
    if smooth:
        b = ring(r0, y0, th)
        ub = np.stack([th * rm, np.full_like(th, -y0)], axis=1)
        if r1 > 0:
            t = ring(r1, y1, th)
            v = np.concatenate([b, t])
            uv = np.concatenate([ub, np.stack([th * rm, np.full_like(th, -y1)], axis=1)])
            n = np.concatenate([slant(th), slant(th)])
            T = seg + 1
            f = np.concatenate([np.stack([j, j + 1, T + j + 1], 1), np.stack([j, T + j + 1, T + j], 1)])
        else:  # one apex vertex per segment, normal at the segment's middle angle
            tm = th[:-1] + np.pi / seg
            apex = np.tile([0.0, y1, 0.0], (seg, 1))
            v = np.concatenate([b, apex])
            uv = np.concatenate([ub, np.stack([tm * rm, np.full_like(tm, -y1)], axis=1)])
            n = np.concatenate([slant(th), slant(tm)])
            f = np.stack([j, j + 1, seg + 1 + j], 1)
        parts.append(_Geom(v, f, uv, n))
    else:
        b = ring(r0, y0, th)
        t = ring(r1, y1, th)
        for k in range(seg):
            if r1 > 0:
                v = np.stack([b[k], b[k + 1], t[k + 1], t[k]])
                f = np.array([[0, 1, 2], [0, 2, 3]])
            else:
                v = np.stack([b[k], b[k + 1], t[k]])
                f = np.array([[0, 1, 2]])
            nrm = np.cross(v[1] - v[0], v[2] - v[0])
            nrm /= np.linalg.norm(nrm)
            # u along the face's bottom edge, v down its slant (metres).
            e = (v[1] - v[0]) / np.linalg.norm(v[1] - v[0])
            w = np.cross(nrm, e)
            uv = np.stack([(v - v[0]) @ e, -((v - v[0]) @ w)], axis=1)
            parts.append(_Geom(v, f, uv, np.tile(nrm, (len(v), 1))))
    if caps:
        cb = ring(r0, y0, th[:-1])
        v = np.concatenate([[[0.0, y0, 0.0]], cb])
        f = np.stack([np.zeros(seg, dtype=np.int64), 1 + (j + 1) % seg, 1 + j], 1)
        parts.append(_Geom(v, f, v[:, [0, 2]], np.tile([0.0, -1.0, 0.0], (seg + 1, 1))))
        if r1 > 0:
            ct = ring(r1, y1, th[:-1])
            v = np.concatenate([[[0.0, y1, 0.0]], ct])
            f = np.stack([np.zeros(seg, dtype=np.int64), 1 + j, 1 + (j + 1) % seg], 1)
            parts.append(_Geom(v, f, v[:, [0, 2]], np.tile([0.0, 1.0, 0.0], (seg + 1, 1))))
    return _cat(parts, one_solid=True)


def _ellipsoid(radii, center, n_lat: int = 8, n_lon: int = 16, hemi: bool = False) -> _Geom:
    """UV ellipsoid with smooth normals; ``hemi`` keeps the top half and closes it with a disc."""
    a, b, c = (float(r) for r in radii)
    phi_max = 0.5 * np.pi if hemi else np.pi
    phi = phi_max * np.arange(n_lat + 1) / n_lat  # 0 = top pole
    th = 2.0 * np.pi * np.arange(n_lon + 1) / n_lon
    P, T = np.meshgrid(phi, th, indexing="ij")
    v = np.stack([a * np.sin(P) * np.sin(T), b * np.cos(P), c * np.sin(P) * np.cos(T)], -1).reshape(-1, 3)
    n = v / np.array([a * a, b * b, c * c])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    uv = np.stack([T * (a + c) / 2, -P * b], -1).reshape(-1, 2)
    L = n_lon + 1
    faces = []
    j = np.arange(n_lon)
    for k in range(n_lat):
        up, lo = k * L + j, (k + 1) * L + j
        if not (k == n_lat - 1 and not hemi):  # collapses at the bottom pole
            faces.append(np.stack([up, lo, lo + 1], 1))
        if k > 0:  # collapses at the top pole
            faces.append(np.stack([up, lo + 1, up + 1], 1))
    g = _Geom(v, np.concatenate(faces), uv, n)
    if hemi:
        ring = v[n_lat * L : n_lat * L + n_lon]
        cv = np.concatenate([[[0.0, 0.0, 0.0]], ring])
        j = np.arange(n_lon)
        cf = np.stack([np.zeros(n_lon, dtype=np.int64), 1 + (j + 1) % n_lon, 1 + j], 1)
        g = _cat([g, _Geom(cv, cf, cv[:, [0, 2]], np.tile([0.0, -1.0, 0.0], (n_lon + 1, 1)))], one_solid=True)
    return _xf(g, None, center)


def _clean_polygon(poly: np.ndarray) -> np.ndarray:
    """Drop repeated and collinear vertices; return counter-clockwise ``(n, 2)``."""
    p = np.asarray(poly, dtype=np.float64)
    keep = np.linalg.norm(p - np.roll(p, 1, axis=0), axis=1) > 1e-9
    p = p[keep]
    changed = True
    while changed and len(p) > 3:
        a, b, c = np.roll(p, 1, axis=0), p, np.roll(p, -1, axis=0)
        cr = (b - a)[:, 0] * (c - b)[:, 1] - (b - a)[:, 1] * (c - b)[:, 0]
        scale = np.linalg.norm(b - a, axis=1) * np.linalg.norm(c - b, axis=1)
        straight = (np.abs(cr) <= 1e-10 * np.maximum(scale, 1e-30)) & (np.einsum("ij,ij->i", b - a, c - b) > 0)
        changed = bool(straight.any())
        if changed:
            p = p[~straight]
    if len(p) < 3:
        raise ValueError("polygon has fewer than 3 distinct, non-collinear vertices")
    area2 = np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1])
    return p if area2 > 0 else p[::-1].copy()


def _triangulate(p: np.ndarray) -> np.ndarray:
    """Ear clipping of a simple counter-clockwise polygon ``(n, 2)`` -> ``(n - 2, 3)``."""
    idx = list(range(len(p)))
    tris: list[tuple[int, int, int]] = []
    while len(idx) > 3:
        m = len(idx)
        for k in range(m):
            i0, i1, i2 = idx[k - 1], idx[k], idx[(k + 1) % m]
            a, b, c = p[i0], p[i1], p[i2]
            if (b[0] - a[0]) * (c[1] - b[1]) - (b[1] - a[1]) * (c[0] - b[0]) <= 1e-12:
                continue  # reflex or flat corner: not an ear
            others = p[[j for j in idx if j not in (i0, i1, i2)]]
            if len(others):
                # Inside test for the CCW triangle: left of (or on) all three edges. A
                # vertex on an edge also blocks the ear (it would leave a T-junction).
                d1 = (b[0] - a[0]) * (others[:, 1] - a[1]) - (b[1] - a[1]) * (others[:, 0] - a[0])
                d2 = (c[0] - b[0]) * (others[:, 1] - b[1]) - (c[1] - b[1]) * (others[:, 0] - b[0])
                d3 = (a[0] - c[0]) * (others[:, 1] - c[1]) - (a[1] - c[1]) * (others[:, 0] - c[0])
                if np.any((d1 >= -1e-12) & (d2 >= -1e-12) & (d3 >= -1e-12)):
                    continue
            tris.append((i0, i1, i2))
            idx.pop(k)
            break
        else:
            raise ValueError("ear clipping failed: the polygon is not simple")
    tris.append((idx[0], idx[1], idx[2]))
    return np.asarray(tris, dtype=np.int64)


def _extrude(poly, z0: float, z1: float) -> _Geom:
    """Prism: a simple 2D polygon in the XY plane swept along Z from z0 to z1 (flat normals)."""
    p = _clean_polygon(poly)
    if not z1 > z0:
        raise ValueError(f"extrusion needs z1 > z0, got {z0}, {z1}")
    n = len(p)
    tri = _triangulate(p)
    front = np.column_stack([p, np.full(n, z1)])
    back = np.column_stack([p, np.full(n, z0)])
    uvc = np.stack([p[:, 0], -p[:, 1]], axis=1)
    parts = [
        _Geom(front, tri, uvc, np.tile([0.0, 0.0, 1.0], (n, 1))),
        _Geom(back, tri[:, ::-1].copy(), uvc, np.tile([0.0, 0.0, -1.0], (n, 1))),
    ]
    q = np.roll(p, -1, axis=0)
    d = q - p
    ln = np.linalg.norm(d, axis=1)
    s = np.concatenate([[0.0], np.cumsum(ln)[:-1]])
    v = np.stack([np.column_stack([p, np.full(n, z0)]), np.column_stack([q, np.full(n, z0)]),
                  np.column_stack([q, np.full(n, z1)]), np.column_stack([p, np.full(n, z1)])], axis=1)
    nrm = np.column_stack([d[:, 1], -d[:, 0], np.zeros(n)]) / ln[:, None]  # right of a CCW edge = outside
    uv = np.stack([np.stack([s, np.full(n, -z0)], 1), np.stack([s + ln, np.full(n, -z0)], 1),
                   np.stack([s + ln, np.full(n, -z1)], 1), np.stack([s, np.full(n, -z1)], 1)], axis=1)
    f = np.concatenate([np.stack([4 * np.arange(n), 4 * np.arange(n) + 1, 4 * np.arange(n) + 2], 1),
                        np.stack([4 * np.arange(n), 4 * np.arange(n) + 2, 4 * np.arange(n) + 3], 1)])
    parts.append(_Geom(v.reshape(-1, 3), f, uv.reshape(-1, 2), np.repeat(nrm, 4, axis=0)))
    return _cat(parts, one_solid=True)


def _extrude_x(profile_zy, x0: float, x1: float) -> _Geom:
    """Prism whose profile lies in the (z, y) plane, swept along X from x0 to x1."""
    # Profile (a, y) extruded along e in [-x1, -x0]; rotating about Y by -90 deg maps
    # (a, y, e) -> (-e, y, a): a proper rotation, so orientation is kept.
    g = _extrude(profile_zy, -x1, -x0)
    return _xf(g, _ry(-0.5 * np.pi))


def _arch_profile(width: float, height: float, openings: list[tuple[float, float, float, str]],
                  n_arc: int = 10) -> np.ndarray:
    """Wall elevation with arched openings cut from the bottom edge, in the XY plane.

    Args:
        width, height: outer rectangle [-width/2, width/2] x [0, height].
        openings: ``(x_centre, opening_width, springing_height, "round"|"pointed")``,
            non-overlapping, each inside the wall with its crown below ``height``.

    Returns:
        ``(n, 2)`` counter-clockwise simple polygon.
    """
    pts = [(-width / 2, 0.0)]
    for xc, w, hs, shape in sorted(openings):
        r = w / 2
        pts += [(xc - r, 0.0), (xc - r, hs)]
        if shape == "round":
            a = np.linspace(np.pi, 0.0, n_arc + 1)[1:-1]
            pts += list(zip(xc + r * np.cos(a), hs + r * np.sin(a)))
        else:  # equilateral pointed arch: two arcs of radius w centred on the springings
            h = n_arc // 2
            a = np.linspace(np.pi, 2 * np.pi / 3, h + 1)[1:]  # left arc, up to the apex
            pts += list(zip(xc + r + w * np.cos(a), hs + w * np.sin(a)))
            a = np.linspace(np.pi / 3, 0.0, h + 1)[1:-1]
            pts += list(zip(xc - r + w * np.cos(a), hs + w * np.sin(a)))
        pts += [(xc + r, hs), (xc + r, 0.0)]
    pts += [(width / 2, 0.0), (width / 2, height), (-width / 2, height)]
    return np.asarray(pts)


def _arch_crown(w: float, hs: float, shape: str) -> float:
    return hs + (w / 2 if shape == "round" else w * math.sqrt(3) / 2)


def _stairs_profile(n: int, rise: float, run: float) -> np.ndarray:
    """Flight of ``n`` steps in the (z, y) plane: bottom step at z in [(n-1) run, n run]."""
    pts = [(0.0, 0.0), (n * run, 0.0)]
    for k in range(1, n + 1):
        pts += [((n - k + 1) * run, k * rise), ((n - k) * run, k * rise)]
    return np.asarray(pts)


def _gable_profile(half_span: float, rise: float) -> np.ndarray:
    return np.array([(-half_span, 0.0), (half_span, 0.0), (0.0, rise)])


def _pyramid(half_x: float, half_z: float, y0: float, height: float, top_frac: float = 0.0) -> _Geom:
    """Four-sided pyramid (or truncated: mansard) over a rectangle, flat faces."""
    g = _frustum(math.sqrt(2.0), math.sqrt(2.0) * top_frac, 0.0, 1.0, 4, smooth=False, phase=np.pi / 4)
    return _xf(g, np.diag([half_x, height, half_z]), (0.0, y0, 0.0))
