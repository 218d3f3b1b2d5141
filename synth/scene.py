"""Seeded procedural outdoor scenes: a landmark on a textured ground, props and trees.

World frame: Y up, ground plane y = 0, metres. The landmark stands around the origin;
its *front* (the side a tourist photographs first) faces ``(sin(front_yaw), 0,
cos(front_yaw))``.

A scene is a list of :class:`Part` s, each a triangle mesh with per-vertex UVs and
normals and one :class:`Material`; a part is a union of closed primitives (the ground,
a single square, excepted). Ten landmark types are
composed from primitives (boxes, frusta, ellipsoids, extrusions of 2D profiles,
arches cut into profiles, stairs from profiles or stacked boxes)::

    building, tower, temple, colonnade, arch, wall, monument, rotunda, terrace, pavilion

Each type draws its proportions, counts and sub-variants (roof, top, plan, arch shape,
wings, porticos...) from continuous and discrete distributions, then the whole
landmark gets a random yaw, 0-3 props (statues on pedestals, obelisks, fountains, low
walls) and optionally 0-9 trees (cone, ellipsoid or stacked crowns on cylinder
trunks), so no two seeds share one shape. Textures come from :mod:`synth.textures`.

Geometry is meant to read at 64-128 px: the smallest features (windows, merlons,
column shafts) are about 0.4 m or larger. Flat parts carry face normals (their
vertices are split per face); frusta, spheres and domes carry smooth analytic normals.
Every primitive is closed and outward-oriented once coincident vertices are merged
(UV seams and normal creases split them); see :func:`closed_solids`.

Ground: a square of side ``ground_size`` (default 2 km) centred on the landmark. A
camera at height h sees its far edge ``atan(h / 1000 m)`` below the true horizon:
0.09 deg at 1.5 m, 1.7 deg at 30 m (under one pixel at 128 px and 60 deg FOV for
eye heights below ~8 m), so the horizon looks flat and straight. Its texture is twice
the size of the others over a twice larger tile, so its repetition is less visible.

:func:`to_mitsuba` turns a :class:`SceneSpec` into the shapes part of a Mitsuba scene
dict (in-memory meshes, bitmap albedo textures read raw, i.e. without sRGB decoding).
Everything is seeded: the same seed gives the same bytes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import ModuleType
from typing import Any, Callable

import numpy as np
import trimesh

from . import textures as tx

__all__ = [
    "DEFAULT_GROUND_SIZE",
    "LANDMARK_TYPES",
    "MATERIAL_KINDS",
    "ROLES",
    "Material",
    "Part",
    "SceneSpec",
    "closed_solids",
    "generate_scene",
    "material_to_mitsuba",
    "to_mitsuba",
]

MATERIAL_KINDS = ("diffuse", "roughplastic", "roughconductor")
ROLES = ("landmark", "prop", "tree", "ground")
LANDMARK_TYPES = (
    "building",
    "tower",
    "temple",
    "colonnade",
    "arch",
    "wall",
    "monument",
    "rotunda",
    "terrace",
    "pavilion",
)
DEFAULT_GROUND_SIZE = 2000.0

Rng = np.random.Generator


# --------------------------------------------------------------------------------------
# Public data classes
# --------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Material:
    """A surface material with a spatially varying albedo texture.

    Attributes:
        kind: ``"diffuse"`` (Lambertian), ``"roughplastic"`` (the texture is the
            diffuse reflectance under a GGX dielectric coating, IOR 1.5) or
            ``"roughconductor"`` (GGX metal with Fresnel factor 1 tinted by the
            texture: ``material='none'`` times ``specular_reflectance``).
        texture: float32 ``(S, S, 3)`` linear-RGB albedo in [0.03, 0.85].
        roughness: GGX alpha in (0, 1] for the non-Lambertian kinds; 0 for diffuse.
        texture_kind: name of the texture generator (e.g. ``"brick"``).
        tile_m: metres of surface covered by one texture repeat.
        name: the material slot it fills (e.g. ``"walls"``).
    """

    kind: str
    texture: np.ndarray
    roughness: float = 0.0
    texture_kind: str = "custom"
    tile_m: float = 1.0
    name: str = ""

    def __post_init__(self) -> None:
        if self.kind not in MATERIAL_KINDS:
            raise ValueError(f"material kind must be one of {MATERIAL_KINDS}, got {self.kind!r}")
        t = self.texture
        if not (isinstance(t, np.ndarray) and t.dtype == np.float32 and t.ndim == 3 and t.shape[2] == 3):
            raise ValueError(f"texture must be a float32 (S, S, 3) array, got {getattr(t, 'dtype', type(t))} "
                             f"{getattr(t, 'shape', '')}")
        if t.shape[0] != t.shape[1] or t.shape[0] < 1:
            raise ValueError(f"texture must be square, got shape {t.shape}")
        if not np.isfinite(t).all() or t.min() < 0.0 or t.max() > 1.0:
            raise ValueError("texture albedo must be finite and within [0, 1]")
        if self.kind == "diffuse":
            if self.roughness != 0.0:
                raise ValueError(f"a diffuse material has no roughness (use 0), got {self.roughness}")
        elif not 0.0 < self.roughness <= 1.0:
            raise ValueError(f"roughness (GGX alpha) must lie in (0, 1] for {self.kind}, got {self.roughness}")
        if not self.tile_m > 0.0:
            raise ValueError(f"tile_m must be positive, got {self.tile_m}")

    def describe(self) -> dict[str, Any]:
        """JSON-serialisable summary (no texels)."""
        return {
            "name": self.name,
            "kind": self.kind,
            "texture_kind": self.texture_kind,
            "roughness": float(self.roughness),
            "tile_m": float(self.tile_m),
            "texture_size": int(self.texture.shape[0]),
            "mean_albedo": [round(float(c), 4) for c in self.texture.reshape(-1, 3).mean(axis=0)],
        }


@dataclass(frozen=True, eq=False)
class Part:
    """One named mesh of a scene with a single material.

    Attributes:
        name: unique within the scene (used as the Mitsuba shape id).
        mesh: ``trimesh.Trimesh`` (not processed: vertices split at UV seams and
            normal creases) with ``mesh.visual.uv`` ``(V, 2)`` texture coordinates
            (metres / ``material.tile_m``) and ``mesh.vertex_normals`` ``(V, 3)``.
        material: its :class:`Material`.
        role: ``"landmark"``, ``"prop"``, ``"tree"`` or ``"ground"``.
        solid_ids: ``(F,)`` int64: which primitive (box, frustum, extrusion...) each
            face belongs to. Each primitive is a closed solid on its own; primitives
            may touch or overlap (then their union is not a manifold mesh).
    """

    name: str
    mesh: trimesh.Trimesh
    material: Material
    role: str = "landmark"
    solid_ids: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.role not in ROLES:
            raise ValueError(f"part role must be one of {ROLES}, got {self.role!r}")
        uv = getattr(self.mesh.visual, "uv", None)
        if uv is None or len(uv) != len(self.mesh.vertices):
            raise ValueError(f"part {self.name!r}: the mesh needs one UV per vertex")
        ids = np.zeros(len(self.mesh.faces), dtype=np.int64) if self.solid_ids is None else np.asarray(self.solid_ids)
        if ids.shape != (len(self.mesh.faces),):
            raise ValueError(f"part {self.name!r}: solid_ids must have one entry per face, got {ids.shape}")
        object.__setattr__(self, "solid_ids", ids.astype(np.int64, copy=False))

    @property
    def uv(self) -> np.ndarray:
        """``(V, 2)`` float64 texture coordinates."""
        return np.asarray(self.mesh.visual.uv, dtype=np.float64)

    @property
    def normals(self) -> np.ndarray:
        """``(V, 3)`` float64 unit vertex normals (shading normals)."""
        return np.asarray(self.mesh.vertex_normals, dtype=np.float64)


@dataclass(eq=False)
class SceneSpec:
    """A generated scene: parts plus what cameras and the dataset writer need.

    Attributes:
        seed: the seed it was generated from.
        landmark_type: one of :data:`LANDMARK_TYPES`.
        parts: all meshes; the ground is the part with role ``"ground"``.
        landmark_bounds: ``(2, 3)`` world AABB (min, max) of the landmark parts.
        ground_size: side of the square ground in metres.
        front_yaw: radians; the landmark's front faces ``(sin, 0, cos)`` of it.
        obstacles: ``(N, 4)`` rows ``(x, z, radius, top_y)`` bounding each prop and
            tree as a vertical cylinder (cameras keep out of them).
        glossy_fraction, trees: the generation flags.
        params: JSON-serialisable landmark parameters (proportions, variants).
    """

    seed: int
    landmark_type: str
    parts: list[Part]
    landmark_bounds: np.ndarray
    ground_size: float
    front_yaw: float = 0.0
    obstacles: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    glossy_fraction: float = 0.0
    trees: bool = True
    params: dict[str, Any] = field(default_factory=dict)

    @property
    def landmark_center(self) -> np.ndarray:
        """``(3,)`` centre of the landmark AABB."""
        return 0.5 * (self.landmark_bounds[0] + self.landmark_bounds[1])

    @property
    def landmark_radius(self) -> float:
        """Radius of the sphere around the landmark AABB (half its diagonal), metres."""
        return float(0.5 * np.linalg.norm(self.landmark_bounds[1] - self.landmark_bounds[0]))

    def part(self, name: str) -> Part:
        """The part called ``name`` (KeyError otherwise)."""
        for p in self.parts:
            if p.name == name:
                return p
        raise KeyError(f"no part named {name!r}; parts: {[p.name for p in self.parts]}")

    def parts_with_role(self, role: str) -> list[Part]:
        """Parts whose role is ``role``."""
        if role not in ROLES:
            raise ValueError(f"role must be one of {ROLES}, got {role!r}")
        return [p for p in self.parts if p.role == role]

    def describe(self) -> dict[str, Any]:
        """JSON-serialisable summary for ``scene.json``: type, bounds, parts, materials."""
        return {
            "seed": int(self.seed),
            "landmark_type": self.landmark_type,
            "landmark_bounds": np.asarray(self.landmark_bounds, dtype=float).round(4).tolist(),
            "landmark_radius": round(self.landmark_radius, 4),
            "front_yaw_deg": round(math.degrees(self.front_yaw), 4),
            "ground_size": float(self.ground_size),
            "glossy_fraction": float(self.glossy_fraction),
            "trees": bool(self.trees),
            "params": self.params,
            "parts": [
                {
                    "name": p.name,
                    "role": p.role,
                    "n_vertices": int(len(p.mesh.vertices)),
                    "n_faces": int(len(p.mesh.faces)),
                    "material": p.material.describe(),
                }
                for p in self.parts
            ],
        }


def closed_solids(part: Part) -> list[trimesh.Trimesh]:
    """The part's primitives as separate meshes with coincident vertices merged.

    Parts are built with vertices split at UV seams and normal creases; merging them
    gives, for every role except ``"ground"``, closed outward-oriented solids
    (watertight, winding-consistent, positive volume), one per entry of ``solid_ids``.
    """
    out = []
    for sid in np.unique(part.solid_ids):
        faces = np.asarray(part.mesh.faces)[part.solid_ids == sid]
        m = trimesh.Trimesh(np.asarray(part.mesh.vertices), faces, process=False)
        m.remove_unreferenced_vertices()
        m.merge_vertices(digits_vertex=6)
        out.append(m)
    return out


# --------------------------------------------------------------------------------------
# Geometry kernel: vertices, faces, UVs in metres, normals
# --------------------------------------------------------------------------------------


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


# --------------------------------------------------------------------------------------
# Materials and the landmark builder
# --------------------------------------------------------------------------------------

_SLOT_KINDS: dict[str, tuple[str, ...]] = {
    "walls": ("brick", "plaster", "painted", "stone"),
    "trim": ("stone", "marble", "plaster"),
    "roof": ("roof_tiles", "roof_tiles", "bronze", "stone"),
    "window": ("window",),
    "masonry": ("stone", "stone", "brick", "marble"),
    "marble": ("marble", "stone"),
    "statue": ("bronze", "marble", "stone"),
    "paving": ("paving", "stone", "marble"),
    "ground": ("grass", "grass", "dirt", "paving"),
    "bark": ("bark",),
    "foliage": ("foliage",),
}


class _Palette:
    """Lazily draws one diffuse material per slot name from the texture generator."""

    def __init__(self, rng: Rng, size: int) -> None:
        self.rng, self.size = rng, size
        self.mats: dict[str, Material] = {}

    def get(self, slot: str, kinds: tuple[str, ...] | None = None) -> Material:
        if slot not in self.mats:
            kinds = kinds or _SLOT_KINDS[slot]
            kind = kinds[int(self.rng.integers(len(kinds)))]
            # The ground fills much of every view: twice the texels over twice the tile
            # (same texel density) halves how often its pattern visibly repeats.
            scale = 2 if slot == "ground" else 1
            tex = tx.random_material_texture(self.rng, kind, scale * self.size)
            self.mats[slot] = Material("diffuse", tex, 0.0, kind, scale * tx.TILE_METRES[kind], slot)
        return self.mats[slot]


class _Builder:
    """Collects geometry per part name, each part tied to a palette slot."""

    def __init__(self, palette: _Palette, prefix: str) -> None:
        self.palette, self.prefix = palette, prefix
        self.geoms: dict[str, list[_Geom]] = {}
        self.slots: dict[str, str] = {}

    def add(self, part: str, geom: _Geom, slot: str) -> None:
        name = f"{self.prefix}_{part}"
        if name in self.slots and self.slots[name] != slot:
            raise ValueError(f"part {name} already uses slot {self.slots[name]}, not {slot}")
        self.palette.get(slot)
        self.slots[name] = slot
        self.geoms.setdefault(name, []).append(geom)

    def merged(self) -> dict[str, _Geom]:
        return {k: _cat(v) for k, v in self.geoms.items()}


def _u(r: Rng, a: float, b: float) -> float:
    return float(r.uniform(a, b))


def _ri(r: Rng, a: int, b: int) -> int:
    """Integer in [a, b] inclusive."""
    return int(r.integers(a, b + 1))


def _pick(r: Rng, options):
    return options[int(r.integers(len(options)))]


# ---- reusable pieces ------------------------------------------------------------------


def _stepped_base(b: _Builder, half_x: float, half_z: float, n: int, rise: float, run: float,
                  part: str = "steps", slot: str = "paving") -> float:
    """Stacked boxes, each ``run`` smaller than the one below; returns the top height."""
    for k in range(n):
        g = (n - 1 - k) * run
        b.add(part, _box((-half_x - g, k * rise, -half_z - g), (half_x + g, (k + 1) * rise, half_z + g)), slot)
    return n * rise


def _column(b: _Builder, x: float, z: float, y0: float, height: float, radius: float,
            part: str = "columns", slot: str = "marble", seg: int = 14) -> None:
    """Square base, slightly tapered smooth shaft, square capital."""
    base_h, cap_h = 0.08 * height, 0.07 * height
    w = 1.25 * radius
    b.add(part, _box((x - w, y0, z - w), (x + w, y0 + base_h, z + w)), slot)
    shaft = _frustum(radius, 0.86 * radius, y0 + base_h, y0 + height - cap_h, seg, smooth=True)
    b.add(part, _xf(shaft, None, (x, 0.0, z)), slot)
    b.add(part, _box((x - w, y0 + height - cap_h, z - w), (x + w, y0 + height, z + w)), slot)


def _figure(h: float) -> list[_Geom]:
    """A standing figure of height ``h`` on y = 0 (robe, torso, shoulders, head, arms)."""
    r = 0.16 * h
    gs = [
        _frustum(r, 0.7 * r, 0.0, 0.5 * h, 12),
        _frustum(0.7 * r, 0.62 * r, 0.5 * h, 0.8 * h, 12),
        _box((-0.2 * h, 0.74 * h, -0.07 * h), (0.2 * h, 0.84 * h, 0.07 * h)),
        _ellipsoid((0.07 * h, 0.085 * h, 0.075 * h), (0.0, 0.92 * h, 0.0), 6, 10),
        _box((-0.2 * h, 0.42 * h, -0.05 * h), (-0.12 * h, 0.8 * h, 0.05 * h)),
        # raised arm: a box tilted outwards about the figure's depth axis
        _xf(_box((-0.04 * h, 0.0, -0.04 * h), (0.04 * h, 0.36 * h, 0.04 * h)), _rz(-0.6), (0.16 * h, 0.78 * h, 0.0)),
    ]
    return gs


def _statue_on_pedestal(b: _Builder, r: Rng, x: float, z: float, y0: float, scale: float,
                        part: str = "statue", ped_part: str = "pedestal") -> float:
    """Pedestal (plinth, die, cornice) with a figure, obelisk or sphere; returns the top height."""
    pw, ph = 0.5 * scale * _u(r, 0.8, 1.3), scale * _u(r, 0.9, 1.6)
    b.add(ped_part, _box((x - 1.2 * pw, y0, z - 1.2 * pw), (x + 1.2 * pw, y0 + 0.15 * ph, z + 1.2 * pw)), "trim")
    b.add(ped_part, _box((x - pw, y0 + 0.15 * ph, z - pw), (x + pw, y0 + 0.88 * ph, z + pw)), "trim")
    b.add(ped_part, _box((x - 1.15 * pw, y0 + 0.88 * ph, z - 1.15 * pw), (x + 1.15 * pw, y0 + ph, z + 1.15 * pw)),
          "trim")
    top = y0 + ph
    kind = _pick(r, ("figure", "figure", "obelisk", "sphere"))
    if kind == "figure":
        fh = scale * _u(r, 1.4, 2.2)
        yaw = _u(r, -0.5, 0.5)
        for g in _figure(fh):
            b.add(part, _xf(g, _ry(yaw), (x, top, z)), "statue")
        return top + fh
    if kind == "obelisk":
        oh = scale * _u(r, 2.5, 4.5)
        ob = _frustum(0.8 * pw * math.sqrt(2), 0.5 * pw * math.sqrt(2), 0.0, oh, 4, smooth=False, phase=np.pi / 4)
        tip = _frustum(0.5 * pw * math.sqrt(2), 0.0, oh, oh + 0.6 * pw, 4, smooth=False, phase=np.pi / 4)
        b.add(part, _xf(ob, None, (x, top, z)), "statue")
        b.add(part, _xf(tip, None, (x, top, z)), "statue")
        return top + oh + 0.6 * pw
    rad = 0.9 * pw
    b.add(part, _ellipsoid((rad, rad, rad), (x, top + rad, z), 8, 14), "statue")
    return top + 2 * rad


def _windows_on_block(b: _Builder, cx: float, cz: float, w: float, d: float, rows: list[float],
                      win_w: float, win_h: float, spacing: float, skip: Callable[[float, float], bool],
                      door_gap: float = 0.0) -> None:
    """Dark window slabs (protruding 4 cm) on the four faces of a box block.

    ``rows`` are window centre heights; ``skip(x, z)`` hides windows whose centre lies
    inside another block; ``door_gap`` clears the middle of the front ground floor.
    """
    out = 0.04
    for axis, sign in ((2, 1), (2, -1), (0, 1), (0, -1)):
        length = w if axis == 2 else d
        n = max(1, int((length - 1.0) // spacing))
        hs = (np.arange(n) + 0.5) * length / n - length / 2
        for ri_, yc in enumerate(rows):
            for hpos in hs:
                if axis == 2 and sign > 0 and ri_ == 0 and abs(hpos) < door_gap:
                    continue
                if axis == 2:
                    x, z = cx + hpos, cz + sign * d / 2
                    lo = (x - win_w / 2, yc - win_h / 2, z - 0.1 if sign > 0 else z - out)
                    hi = (x + win_w / 2, yc + win_h / 2, z + out if sign > 0 else z + 0.1)
                    cxz = (x, cz + sign * (d / 2 + 0.5))
                else:
                    x, z = cx + sign * w / 2, cz + hpos
                    lo = (x - 0.1 if sign > 0 else x - out, yc - win_h / 2, z - win_w / 2)
                    hi = (x + out if sign > 0 else x + 0.1, yc + win_h / 2, z + win_w / 2)
                    cxz = (cx + sign * (w / 2 + 0.5), z)
                if skip(*cxz):
                    continue
                b.add("windows", _box(lo, hi), "window")


def _roof(b: _Builder, kind: str, cx: float, cz: float, w: float, d: float, y0: float, r: Rng) -> float:
    """A roof over the block ``[cx -+ w/2] x [cz -+ d/2]`` starting at ``y0``; returns its top."""
    oh = _u(r, 0.2, 0.6)
    if kind == "flat":
        b.add("cornice", _box((cx - w / 2 - oh, y0, cz - d / 2 - oh), (cx + w / 2 + oh, y0 + 0.5, cz + d / 2 + oh)),
              "trim")
        b.add("cornice", _box((cx - w / 2, y0 + 0.5, cz - d / 2), (cx + w / 2, y0 + 1.1, cz + d / 2)), "trim")
        return y0 + 1.1
    pitch = math.radians(_u(r, 22.0, 40.0))
    if kind == "gable":
        if w >= d:  # ridge along x
            hs = d / 2 + oh
            rise = hs * math.tan(pitch)
            g = _extrude_x(_gable_profile(hs, rise), -w / 2 - oh, w / 2 + oh)
        else:
            hs = w / 2 + oh
            rise = hs * math.tan(pitch)
            g = _extrude(_gable_profile(hs, rise), -d / 2 - oh, d / 2 + oh)
        b.add("roof", _xf(g, None, (cx, y0, cz)), "roof")
        return y0 + rise
    top_frac = 0.0 if kind == "hip" else _u(r, 0.45, 0.7)  # mansard: truncated
    rise = (min(w, d) / 2 + oh) * math.tan(pitch) * (1.0 if kind == "hip" else 1.6)
    b.add("roof", _xf(_pyramid(w / 2 + oh, d / 2 + oh, 0.0, rise, top_frac), None, (cx, y0, cz)), "roof")
    return y0 + rise


# ---- landmark types (local frame: front faces +z, base on y = 0) -----------------------


def _build_building(r: Rng, b: _Builder) -> dict[str, Any]:
    storeys = _ri(r, 1, 4)
    sh = _u(r, 3.0, 4.2)
    W, D = _u(r, 8.0, 22.0), _u(r, 6.0, 14.0)
    H = storeys * sh
    blocks = [(0.0, 0.0, W, D, storeys)]
    wings = _pick(r, ("none", "side", "both", "back"))
    if wings in ("side", "both"):
        w2, d2 = W * _u(r, 0.3, 0.6), D * _u(r, 0.5, 0.9)
        st2 = max(1, storeys - _ri(r, 0, 2))
        sides = (1, -1) if wings == "both" else (_pick(r, (1, -1)),)
        for s in sides:
            blocks.append((s * (W / 2 + w2 / 2 - 0.3), -(D - d2) / 2, w2, d2, st2))
    elif wings == "back":
        w2, d2 = W * _u(r, 0.3, 0.7), D * _u(r, 0.4, 1.0)
        blocks.append((0.0, -(D / 2 + d2 / 2 - 0.3), w2, d2, max(1, storeys - _ri(r, 0, 1))))
    roof = _pick(r, ("gable", "gable", "hip", "mansard", "flat"))
    win_w, win_h = _u(r, 0.8, 1.5), min(_u(r, 1.2, 2.1), 0.6 * sh)
    spacing = _u(r, 2.4, 4.0)
    plinth_h = _u(r, 0.4, 1.0)

    def inside_other(k: int) -> Callable[[float, float], bool]:
        def f(x: float, z: float) -> bool:
            for j, (cx, cz, w, d, _) in enumerate(blocks):
                if j != k and abs(x - cx) < w / 2 and abs(z - cz) < d / 2:
                    return True
            return False
        return f

    door_w = _u(r, 1.2, 2.4)
    for k, (cx, cz, w, d, st) in enumerate(blocks):
        h = st * sh
        b.add("walls", _box((cx - w / 2, 0.0, cz - d / 2), (cx + w / 2, h, cz + d / 2)), "walls")
        b.add("plinth", _box((cx - w / 2 - 0.12, 0.0, cz - d / 2 - 0.12),
                             (cx + w / 2 + 0.12, plinth_h, cz + d / 2 + 0.12)),
              "trim")
        rows = [i * sh + 0.55 * sh for i in range(st)]
        _windows_on_block(b, cx, cz, w, d, rows, win_w, win_h, spacing, inside_other(k),
                          door_gap=door_w if k == 0 else 0.0)
        _roof(b, roof, cx, cz, w, d, h, r)
    b.add("door", _box((-door_w / 2, 0.0, D / 2 - 0.1), (door_w / 2, min(0.8 * sh, 3.0), D / 2 + 0.06)), "window")
    tower = r.random() < 0.25
    if tower:  # small clock/bell tower rising from the front of the main block
        tw = _u(r, 2.5, 4.0)
        th = H + _u(r, 3.0, 8.0)
        z0 = D / 2 - tw
        b.add("tower", _box((-tw / 2, 0.0, z0 - tw / 2), (tw / 2, th, z0 + tw / 2)), "trim")
        b.add("roof", _pyramid(tw / 2 + 0.3, tw / 2 + 0.3, th, _u(r, 1.5, 4.0)), "roof")
    return {"storeys": storeys, "width": W, "depth": D, "wings": wings, "roof": roof, "tower": tower}


def _build_tower(r: Rng, b: _Builder) -> dict[str, Any]:
    plan = _pick(r, ("square", "octagon", "round"))
    w = _u(r, 4.0, 9.0)
    H = _u(r, 15.0, 40.0)
    tiers = _ri(r, 2, 4)
    heights = H * r.dirichlet(np.full(tiers, 3.0))
    shrink = _u(r, 0.75, 0.95)
    top = _pick(r, ("spire", "crenellations", "dome", "belfry"))
    y, width = 0.0, w

    def body(hw: float, y0: float, y1: float) -> _Geom:
        if plan == "square":
            return _box((-hw, y0, -hw), (hw, y1, hw))
        if plan == "octagon":
            return _frustum(hw / math.cos(np.pi / 8), hw / math.cos(np.pi / 8), y0, y1, 8, smooth=False,
                            phase=np.pi / 8)
        return _frustum(hw, hw, y0, y1, 24, smooth=True)

    for k, th in enumerate(heights):
        hw = width / 2
        b.add("body", body(hw, y, y + th), "masonry")
        # slit windows half-way up the tier on four sides
        ww, wh = 0.5 + 0.1 * width, min(0.4 * th, _u(r, 1.2, 2.5))
        for a in range(4):
            gw = _box((-ww / 2, y + 0.5 * th - wh / 2, hw - 0.1), (ww / 2, y + 0.5 * th + wh / 2, hw + 0.05))
            b.add("windows", _xf(gw, _ry(a * np.pi / 2)), "window")
        y += th
        if k < tiers - 1 or top != "belfry":
            c = 1.12 * hw + 0.15
            b.add("cornice", body(c, y - 0.05, y + 0.35), "trim")
            y += 0.35
        width *= shrink if k < tiers - 1 else 1.0
    hw = width / 2
    if top == "spire":
        sh = _u(r, 0.8, 2.5) * width
        g = (_pyramid(hw + 0.2, hw + 0.2, y, sh) if plan == "square"
             else _frustum((hw + 0.2) / math.cos(np.pi / 8), 0.0, y, y + sh, 8, smooth=False, phase=np.pi / 8)
             if plan == "octagon" else _frustum(hw + 0.2, 0.0, y, y + sh, 24, smooth=True))
        b.add("roof", g, "roof")
    elif top == "dome":
        b.add("roof", _ellipsoid((hw, hw * _u(r, 0.8, 1.4), hw), (0.0, y, 0.0), 6, 20, hemi=True), "roof")
    elif top == "crenellations":
        n = max(2, int(round(2 * hw / 1.2)))
        mw = 2 * hw / (2 * n - 1)
        for a in range(4):
            for i in range(n):
                x0 = -hw + 2 * i * mw
                g = _box((x0, y, hw - 0.5), (x0 + mw, y + 1.0, hw))
                b.add("merlons", _xf(g, _ry(a * np.pi / 2)), "masonry")
    else:  # belfry: four corner piers, a slab and a pyramid
        ph = _u(r, 2.5, 4.5)
        pw = 0.22 * width
        for sx in (-1, 1):
            for sz in (-1, 1):
                b.add("belfry", _box((sx * hw - (pw if sx > 0 else 0), y, sz * hw - (pw if sz > 0 else 0)),
                                     (sx * hw + (pw if sx < 0 else 0), y + ph, sz * hw + (pw if sz < 0 else 0))),
                      "masonry")
        b.add("cornice", _box((-hw - 0.2, y + ph, -hw - 0.2), (hw + 0.2, y + ph + 0.4, hw + 0.2)), "trim")
        b.add("roof", _pyramid(hw + 0.3, hw + 0.3, y + ph + 0.4, _u(r, 0.8, 1.8) * width), "roof")
    annex = r.random() < 0.35
    if annex:
        aw, ad, ah = _u(r, 5.0, 12.0), _u(r, 4.0, 8.0), _u(r, 3.0, 6.0)
        ax = w / 2 + aw / 2 - 0.2
        b.add("annex", _box((ax - aw / 2, 0.0, -ad / 2), (ax + aw / 2, ah, ad / 2)), "walls")
        _roof(b, "gable", ax, 0.0, aw, ad, ah, r)
    return {"plan": plan, "width": w, "height": H, "tiers": tiers, "top": top, "annex": annex}


def _build_temple(r: Rng, b: _Builder) -> dict[str, Any]:
    n_front = _pick(r, (4, 6, 6, 8))
    peripteral = r.random() < 0.5
    Hc = _u(r, 5.0, 10.0)
    rad = Hc / _u(r, 8.0, 11.0)
    sp = rad * _u(r, 4.0, 5.5)
    W = (n_front - 1) * sp
    n_side = (n_front + _ri(r, 1, 4)) if peripteral else _ri(r, 2, 3)
    D = (n_side - 1) * sp
    steps = _ri(r, 2, 4)
    rise = _u(r, 0.25, 0.45)
    y0 = _stepped_base(b, W / 2 + 2 * rad, D / 2 + 2 * rad, steps, rise, _u(r, 0.35, 0.6), slot="marble",
                       part="stylobate")
    xs = np.linspace(-W / 2, W / 2, n_front)
    zs = np.linspace(-D / 2, D / 2, n_side)
    for i, x in enumerate(xs):
        for j, z in enumerate(zs):
            on_ring = i in (0, n_front - 1) or j in (0, n_side - 1)
            if (peripteral and on_ring) or (not peripteral and j == n_side - 1):
                _column(b, float(x), float(z), y0, Hc, rad)
    ent_h = 0.2 * Hc
    y1 = y0 + Hc
    m = 1.3 * rad
    b.add("entablature", _box((-W / 2 - m, y1, -D / 2 - m), (W / 2 + m, y1 + ent_h, D / 2 + m)), "marble")
    cella_d = D - (sp if not peripteral else 2 * sp)
    if cella_d > 1.0:
        cz1 = D / 2 - (sp if not peripteral else sp)
        cw = W - (0 if not peripteral else 2 * sp) - 2 * m
        if cw > 1.0:
            b.add("cella", _box((-cw / 2, y0, cz1 - cella_d), (cw / 2, y1, cz1)), "walls")
    pediment = r.random() < 0.75
    top = y1 + ent_h
    if pediment:
        hs = W / 2 + m + 0.2
        rise_p = hs * math.tan(math.radians(_u(r, 12.0, 20.0)))
        g = _extrude(_gable_profile(hs, rise_p), -D / 2 - m - 0.2, D / 2 + m + 0.2)
        b.add("pediment", _xf(g, None, (0.0, top, 0.0)), "marble")
        top += rise_p
    else:
        b.add("entablature", _box((-W / 2 - m + 0.3, top, -D / 2 - m + 0.3),
                                  (W / 2 + m - 0.3, top + 0.8, D / 2 + m - 0.3)),
              "marble")
    return {"columns_front": n_front, "columns_side": n_side, "peripteral": peripteral, "column_height": Hc,
            "pediment": pediment}


def _build_colonnade(r: Rng, b: _Builder) -> dict[str, Any]:
    curved = r.random() < 0.45
    Hc = _u(r, 4.5, 9.0)
    rad = Hc / _u(r, 8.0, 11.0)
    rows = _ri(r, 1, 2)
    ent_h = 0.18 * Hc
    if not curved:
        n = _ri(r, 7, 14)
        sp = rad * _u(r, 4.0, 6.0)
        L = (n - 1) * sp
        depth = (rows - 1) * sp + 4 * rad
        y0 = _stepped_base(b, L / 2 + 2 * rad, depth / 2 + 1.0, _ri(r, 1, 3), 0.3, 0.45, part="steps")
        for k in range(rows):
            z = depth / 2 - 2 * rad - k * sp
            for x in np.linspace(-L / 2, L / 2, n):
                _column(b, float(x), z, y0, Hc, rad)
        b.add("entablature", _box((-L / 2 - 1.3 * rad, y0 + Hc, -depth / 2 - 0.5),
                                  (L / 2 + 1.3 * rad, y0 + Hc + ent_h, depth / 2)), "marble")
        back = r.random() < 0.6
        if back:
            b.add("back_wall", _box((-L / 2 - 1.3 * rad, y0, -depth / 2 - 0.5 - 0.8),
                                    (L / 2 + 1.3 * rad, y0 + Hc + ent_h, -depth / 2 - 0.5)), "walls")
            rz = -depth / 2 - 1.3
            g = _extrude_x(np.array([(rz, 0.0), (depth / 2 + 0.6, 0.0), (rz, _u(r, 1.0, 2.5))]),
                           -L / 2 - 1.6 * rad, L / 2 + 1.6 * rad)
            b.add("roof", _xf(g, None, (0.0, y0 + Hc + ent_h, 0.0)), "roof")
        return {"curved": False, "columns": n, "rows": rows, "length": L, "back_wall": back}
    Rc = _u(r, 10.0, 24.0)
    span = math.radians(_u(r, 70.0, 160.0))
    n = max(5, int(span * Rc / (rad * _u(r, 4.0, 6.0))) + 1)
    angles = np.linspace(-span / 2, span / 2, n)
    y0 = 0.4
    # Curved paving: wedge boxes under each bay, then columns on arcs, entablature chords.
    for k in range(rows):
        Rk = Rc + k * rad * 5.0
        pts = [(Rk * math.sin(a), -Rc + Rk * math.cos(a)) for a in angles]  # arc centred at (0, -Rc): apex at z=0
        for x, z in pts:
            _column(b, x, z, y0, Hc, rad)
        for a0, a1 in zip(angles[:-1], angles[1:]):
            am = 0.5 * (a0 + a1)
            chord = 2 * Rk * math.sin(0.5 * (a1 - a0)) + 2.2 * rad
            c = (Rk * math.cos(0.5 * (a1 - a0))) * np.array([math.sin(am), 0.0, math.cos(am)]) + (0.0, 0.0, -Rc)
            ent = _box((-chord / 2, y0 + Hc, -1.3 * rad), (chord / 2, y0 + Hc + ent_h, 1.3 * rad))
            b.add("entablature", _xf(ent, _ry(am), c), "marble")
            base = _box((-chord / 2, 0.0, -2.0 * rad), (chord / 2, y0, 2.0 * rad))
            b.add("steps", _xf(base, _ry(am), c), "paving")
    return {"curved": True, "columns": n, "rows": rows, "radius": Rc, "span_deg": math.degrees(span)}


def _build_arch(r: Rng, b: _Builder) -> dict[str, Any]:
    W = _u(r, 8.0, 20.0)
    D = _u(r, 3.0, 7.0)
    H = _u(r, 8.0, 18.0)
    shape = _pick(r, ("round", "round", "pointed"))
    triple = r.random() < 0.5 and W > 11
    wc = W * _u(r, 0.3, 0.42)
    hs = H * _u(r, 0.35, 0.5)
    openings = [(0.0, wc, hs, shape)]
    if triple:
        ws = wc * _u(r, 0.4, 0.55)
        xs = 0.5 * (wc / 2 + W / 2)
        openings += [(-xs, ws, hs * 0.6, shape), (xs, ws, hs * 0.6, shape)]
    crown = max(_arch_crown(w, h, s) for _, w, h, s in openings)
    H = max(H, crown + 1.5)
    b.add("body", _extrude(_arch_profile(W, H, openings), -D / 2, D / 2), "masonry")
    b.add("cornice", _box((-W / 2 - 0.3, H, -D / 2 - 0.3), (W / 2 + 0.3, H + 0.5, D / 2 + 0.3)), "trim")
    attic_h = _u(r, 0.15, 0.3) * H
    b.add("attic", _box((-W / 2 + 0.2, H + 0.5, -D / 2 + 0.2), (W / 2 - 0.2, H + 0.5 + attic_h, D / 2 - 0.2)),
          "masonry")
    columns = r.random() < 0.5
    if columns:
        rad = min(0.35, 0.06 * W)
        piers = [-W / 2 + 0.5 * (W / 2 - wc / 2), W / 2 - 0.5 * (W / 2 - wc / 2)] if not triple else \
            [-W / 2 + 0.6 * rad + 0.3, -wc / 2 - 0.6 * rad - 0.2, wc / 2 + 0.6 * rad + 0.2, W / 2 - 0.6 * rad - 0.3]
        for x in piers:
            for z in (D / 2 + 1.1 * rad, -D / 2 - 1.1 * rad):
                _column(b, float(x), z, 0.0, H, rad, slot="trim")
    statue = r.random() < 0.4
    if statue:
        top = H + 0.5 + attic_h
        for g in _figure(_u(r, 2.5, 4.0)):
            b.add("statue", _xf(g, None, (0.0, top, 0.0)), "statue")
    return {"width": W, "depth": D, "height": H, "arch": shape, "openings": len(openings), "columns": columns,
            "statue": statue}


def _build_wall(r: Rng, b: _Builder) -> dict[str, Any]:
    L = _u(r, 25.0, 50.0)
    T = _u(r, 2.0, 4.0)
    H = _u(r, 6.0, 12.0)
    shape = _pick(r, ("round", "pointed"))
    gw = _u(r, 3.0, 5.5)
    hs = min(_u(r, 2.5, 4.5), H - _arch_crown(gw, 0.0, shape) - 1.0)
    hs = max(hs, 1.0)
    H = max(H, _arch_crown(gw, hs, shape) + 1.5)
    b.add("wall", _extrude(_arch_profile(L, H, [(0.0, gw, hs, shape)]), -T / 2, T / 2), "masonry")
    # Merlons along the front edge.
    mw = _u(r, 0.8, 1.3)
    n = int(L / (2 * mw))
    for i in range(n):
        x0 = -L / 2 + 2 * i * mw + 0.5 * mw
        b.add("merlons", _box((x0, H, T / 2 - 0.5), (x0 + mw, H + 1.0, T / 2)), "masonry")
    towers = _pick(r, ("round", "square"))
    tr = _u(r, 2.2, 3.5)
    th = H + _u(r, 3.0, 8.0)
    xs = [-(gw / 2 + tr + 1.0), gw / 2 + tr + 1.0]
    ends = r.random() < 0.5
    if ends:
        xs += [-L / 2, L / 2]
    for x in xs:
        g = (_frustum(tr, tr, 0.0, th, 20) if towers == "round" else _box((-tr, 0.0, -tr), (tr, th, tr)))
        b.add("towers", _xf(g, None, (x, 0.0, 0.4)), "masonry")
        cap = (_frustum(tr + 0.35, tr + 0.35, th, th + 0.6, 20) if towers == "round"
               else _box((-tr - 0.35, th, -tr - 0.35), (tr + 0.35, th + 0.6, tr + 0.35)))
        b.add("cornice", _xf(cap, None, (x, 0.0, 0.4)), "trim")
        if r.random() < 0.5:
            roof = (_frustum(tr + 0.35, 0.0, th + 0.6, th + 0.6 + _u(r, 2.0, 5.0), 20) if towers == "round"
                    else _pyramid(tr + 0.35, tr + 0.35, th + 0.6, _u(r, 2.0, 5.0)))
            b.add("roof", _xf(roof, None, (x, 0.0, 0.4)), "roof")
        for a in range(4):  # arrow slits
            g = _box((-0.25, 0.55 * th, tr - 0.15), (0.25, 0.55 * th + 1.4, tr + 0.05))
            b.add("windows", _xf(g, _ry(a * np.pi / 2 + np.pi / 4 * (towers == "round")), (x, 0.0, 0.4)), "window")
    return {"length": L, "thickness": T, "height": H, "gate": shape, "towers": towers, "end_towers": ends}


def _build_monument(r: Rng, b: _Builder) -> dict[str, Any]:
    base = _u(r, 3.0, 7.0)
    steps = _ri(r, 2, 6)
    y0 = _stepped_base(b, base / 2, base / 2, steps, _u(r, 0.2, 0.4), _u(r, 0.3, 0.6), part="steps")
    top_kind = _pick(r, ("statue", "obelisk", "column", "group"))
    if top_kind == "statue":
        # Pedestal half-width is at most 0.78 x scale: keep it on the top step (base / 2).
        top = _statue_on_pedestal(b, r, 0.0, 0.0, y0, base * _u(r, 0.4, 0.58))
    elif top_kind == "obelisk":
        pw = base * 0.3
        ph = _u(r, 1.5, 3.0)
        b.add("pedestal", _box((-pw, y0, -pw), (pw, y0 + ph, pw)), "trim")
        oh = _u(r, 8.0, 20.0)
        ob = _frustum(0.75 * pw * math.sqrt(2), 0.45 * pw * math.sqrt(2), y0 + ph, y0 + ph + oh, 4, smooth=False,
                      phase=np.pi / 4)
        tip = _frustum(0.45 * pw * math.sqrt(2), 0.0, y0 + ph + oh, y0 + ph + oh + pw, 4, smooth=False, phase=np.pi / 4)
        b.add("obelisk", _cat([ob, tip]), "masonry")
        top = y0 + ph + oh + pw
    elif top_kind == "column":
        pw = base * 0.28
        ph = _u(r, 2.0, 4.0)
        b.add("pedestal", _box((-pw, y0, -pw), (pw, y0 + ph, pw)), "trim")
        ch = _u(r, 10.0, 25.0)
        _column(b, 0.0, 0.0, y0 + ph, ch, 0.75 * pw, part="column", slot="masonry", seg=18)
        top = y0 + ph + ch
        for g in _figure(_u(r, 2.0, 3.5)):
            b.add("statue", _xf(g, _ry(_u(r, -0.5, 0.5)), (0.0, top, 0.0)), "statue")
        top += 3.5
    else:  # group: a central figure flanked by smaller pedestals
        top = _statue_on_pedestal(b, r, 0.0, 0.0, y0, base * 0.28)
        for s in (-1, 1):  # side pedestals: within the top step, clear of the central one
            _statue_on_pedestal(b, r, s * base * 0.35, base * 0.35, y0, base * 0.16)
    return {"base": base, "steps": steps, "top": top_kind, "height": top}


def _build_rotunda(r: Rng, b: _Builder) -> dict[str, Any]:
    R = _u(r, 5.0, 12.0)
    Hd = _u(r, 5.0, 12.0)
    extra = _pick(r, ("none", "portico", "ring"))
    ring_rad = 0.09 * Hd
    ring_r = R + 4.5 * ring_rad
    # The stepped base carries the ring colonnade too, so no column overhangs a step.
    half = (ring_r + 1.5 * ring_rad + 0.5) if extra == "ring" else R + 1.0
    y0 = _stepped_base(b, half, half, _ri(r, 1, 3), 0.35, 0.5, part="steps") if r.random() < 0.5 else 0.0
    b.add("drum", _frustum(R, R, y0, y0 + Hd, 32), "walls")
    b.add("cornice", _frustum(R + 0.4, R + 0.4, y0 + Hd, y0 + Hd + 0.6, 32), "trim")
    n_win = _ri(r, 6, 12)
    wh = min(0.35 * Hd, _u(r, 1.5, 3.0))
    for k in range(n_win):
        g = _box((-0.6, y0 + 0.55 * Hd - wh / 2, R - 0.2), (0.6, y0 + 0.55 * Hd + wh / 2, R + 0.05))
        b.add("windows", _xf(g, _ry(2 * np.pi * (k + 0.5) / n_win)), "window")
    dome = _pick(r, ("dome", "dome", "cone"))
    yd = y0 + Hd + 0.6
    if dome == "dome":
        b.add("dome", _ellipsoid((R, R * _u(r, 0.6, 1.2), R), (0.0, yd, 0.0), 8, 32, hemi=True), "roof")
        top = yd + R
        if r.random() < 0.5:  # lantern
            lr = 0.15 * R
            b.add("lantern", _frustum(lr, lr, top - 0.3 * R, top + 0.2 * R, 16), "trim")
            b.add("dome", _ellipsoid((1.2 * lr,) * 3, (0.0, top + 0.2 * R, 0.0), 6, 16, hemi=True), "roof")
    else:
        b.add("dome", _frustum(R + 0.5, 0.0, yd, yd + R * _u(r, 0.5, 1.0), 32), "roof")
    if extra == "portico":
        n = _pick(r, (4, 6))
        Hc = 0.85 * Hd
        rad = Hc / 10
        sp = min(2 * R * 0.8 / (n - 1), rad * 5.5)
        W = (n - 1) * sp
        zc = R + 2.5 * rad + sp
        pf = max(y0, 0.3)  # the portico's own floor, level with the base top
        b.add("portico_floor", _box((-W / 2 - 1.0, 0.0, R * 0.5), (W / 2 + 1.0, pf, zc + 1.5)), "paving")
        for x in np.linspace(-W / 2, W / 2, n):
            _column(b, float(x), zc, pf, Hc, rad)
        b.add("portico", _box((-W / 2 - 1.3 * rad, pf + Hc, R * 0.5),
                              (W / 2 + 1.3 * rad, pf + 1.2 * Hc, zc + 1.3 * rad)), "trim")
        hs = W / 2 + 1.3 * rad + 0.2
        g = _extrude(_gable_profile(hs, hs * math.tan(math.radians(15))), R * 0.5, zc + 1.5 * rad)
        b.add("pediment", _xf(g, None, (0.0, pf + 1.2 * Hc, 0.0)), "trim")
    elif extra == "ring":
        n = _ri(r, 12, 20)
        for k in range(n):
            a = 2 * np.pi * k / n
            _column(b, ring_r * math.sin(a), ring_r * math.cos(a), y0, 0.8 * Hd, ring_rad)
        rr = ring_r + 1.4 * ring_rad
        b.add("ring_entablature", _frustum(rr, rr, y0 + 0.8 * Hd, y0 + 0.92 * Hd, 32), "trim")
    return {"radius": R, "drum_height": Hd, "roof": dome, "extra": extra}


def _build_terrace(r: Rng, b: _Builder) -> dict[str, Any]:
    W, D = _u(r, 12.0, 26.0), _u(r, 8.0, 18.0)
    Hp = _u(r, 2.0, 5.0)
    b.add("platform", _box((-W / 2, 0.0, -D / 2), (W / 2, Hp, D / 2)), "masonry")
    n = max(4, int(round(Hp / _u(r, 0.15, 0.22))))
    rise = Hp / n
    run = _u(r, 0.3, 0.45)
    sw = _u(r, 0.3, 0.7) * W
    stairs = _xf(_extrude_x(_stairs_profile(n, rise, run), -sw / 2, sw / 2), None, (0.0, 0.0, D / 2 - 0.02))
    b.add("stairs", stairs, "paving")
    # Side walls flanking the flight, and a balustrade-like parapet around the terrace.
    for s in (-1, 1):
        g = _extrude_x(np.array([(0.0, 0.0), (n * run, 0.0), (n * run, 0.9), (0.0, Hp + 0.9)]),
                       s * sw / 2 + (0.0 if s > 0 else -0.6), s * sw / 2 + (0.6 if s > 0 else 0.0))
        b.add("parapet", _xf(g, None, (0.0, 0.0, D / 2 - 0.02)), "trim")
    pt = 0.4
    for x0, x1 in ((-W / 2, -sw / 2 - 0.6), (sw / 2 + 0.6, W / 2)):
        if x1 - x0 > 0.5:
            b.add("parapet", _box((x0, Hp, D / 2 - pt), (x1, Hp + 0.9, D / 2)), "trim")
    b.add("parapet", _box((-W / 2, Hp, -D / 2), (-W / 2 + pt, Hp + 0.9, D / 2 - pt)), "trim")
    b.add("parapet", _box((W / 2 - pt, Hp, -D / 2), (W / 2, Hp + 0.9, D / 2 - pt)), "trim")
    crown = _pick(r, ("pavilion", "building", "statue"))
    if crown == "building":
        bw, bd = W * _u(r, 0.4, 0.7), D * _u(r, 0.3, 0.5)
        bh = _u(r, 3.5, 8.0)
        cz = -D / 2 + bd / 2 + 0.6
        b.add("walls", _box((-bw / 2, Hp, cz - bd / 2), (bw / 2, Hp + bh, cz + bd / 2)), "walls")
        rows = [Hp + 0.55 * bh]
        _windows_on_block(b, 0.0, cz, bw, bd, rows, 1.1, min(1.8, 0.5 * bh), 3.0, lambda x, z: False)
        _roof(b, _pick(r, ("gable", "hip", "flat")), 0.0, cz, bw, bd, Hp + bh, r)
    elif crown == "pavilion":
        pr = 0.22 * min(W, D)
        _pavilion(r, b, 0.0, -D / 2 + pr + 1.5, Hp, pr)  # floor circumradius pr + 0.8 stays on the terrace
    else:
        _statue_on_pedestal(b, r, 0.0, -D / 6, Hp, _u(r, 1.5, 2.5))
    return {"width": W, "depth": D, "platform_height": Hp, "steps": n, "crown": crown}


def _pavilion(r: Rng, b: _Builder, cx: float, cz: float, y0: float, R: float) -> dict[str, Any]:
    n = _pick(r, (4, 6, 8))
    Hc = _u(r, 3.0, 5.5)
    rad = _u(r, 0.18, 0.3)
    b.add("floor", _xf(_frustum(R + 0.8, R + 0.8, y0, y0 + 0.4, n, smooth=False, phase=np.pi / n), None, (cx, 0.0, cz)),
          "paving")
    for k in range(n):
        a = np.pi / n + 2 * np.pi * k / n
        _column(b, cx + R * math.sin(a), cz + R * math.cos(a), y0 + 0.4, Hc, rad, slot="trim")
    yt = y0 + 0.4 + Hc
    b.add("entablature", _xf(_frustum(R + 0.5, R + 0.5, yt, yt + 0.5, n, smooth=False, phase=np.pi / n), None,
                             (cx, 0.0, cz)), "trim")
    roof = _pick(r, ("pyramid", "dome", "tent"))
    if roof == "dome":
        g = _ellipsoid((R + 0.5, _u(r, 0.6, 1.0) * R, R + 0.5), (0.0, yt + 0.5, 0.0), 6, 24, hemi=True)
    else:
        h = (R + 0.6) * (_u(r, 0.6, 1.0) if roof == "pyramid" else _u(r, 1.2, 2.0))
        g = _frustum(R + 0.7, 0.0, yt + 0.5, yt + 0.5 + h, n, smooth=False, phase=np.pi / n)
    b.add("roof", _xf(g, None, (cx, 0.0, cz)), "roof")
    return {"columns": n, "roof": roof, "radius": R}


def _build_pavilion(r: Rng, b: _Builder) -> dict[str, Any]:
    R = _u(r, 2.5, 6.0)
    steps = _ri(r, 0, 3)
    y0 = _stepped_base(b, R + 1.2, R + 1.2, steps, 0.3, 0.4, part="steps") if steps else 0.0
    p = _pavilion(r, b, 0.0, 0.0, y0, R)
    p["steps"] = steps
    return p


_BUILDERS: dict[str, Callable[[Rng, _Builder], dict[str, Any]]] = {
    "building": _build_building,
    "tower": _build_tower,
    "temple": _build_temple,
    "colonnade": _build_colonnade,
    "arch": _build_arch,
    "wall": _build_wall,
    "monument": _build_monument,
    "rotunda": _build_rotunda,
    "terrace": _build_terrace,
    "pavilion": _build_pavilion,
}


# ---- props and trees ------------------------------------------------------------------


def _build_prop(r: Rng, b: _Builder) -> tuple[float, float]:
    """One prop around the local origin; returns (bounding radius, top height)."""
    kind = _pick(r, ("statue", "statue", "obelisk", "fountain", "low_wall"))
    if kind == "statue":
        top = _statue_on_pedestal(b, r, 0.0, 0.0, 0.0, _u(r, 0.8, 1.6), part="statue", ped_part="pedestal")
        return 1.2, top
    if kind == "obelisk":
        w = _u(r, 0.5, 0.9)
        h = _u(r, 4.0, 8.0)
        b.add("pedestal", _box((-1.5 * w, 0.0, -1.5 * w), (1.5 * w, 0.8, 1.5 * w)), "trim")
        ob = _frustum(w * math.sqrt(2), 0.6 * w * math.sqrt(2), 0.8, 0.8 + h, 4, smooth=False, phase=np.pi / 4)
        tip = _frustum(0.6 * w * math.sqrt(2), 0.0, 0.8 + h, 1.3 + h, 4, smooth=False, phase=np.pi / 4)
        b.add("obelisk", _cat([ob, tip]), "masonry")
        return 2.2 * w, 1.3 + h
    if kind == "fountain":
        R = _u(r, 1.5, 3.0)
        b.add("basin", _frustum(R, R, 0.0, 0.6, 24), "trim")
        b.add("basin", _frustum(0.3 * R, 0.25 * R, 0.6, 1.6, 16), "trim")
        b.add("basin", _frustum(0.5 * R, 0.5 * R, 1.6, 1.8, 16), "trim")
        return R, 1.8
    L = _u(r, 4.0, 9.0)
    h = _u(r, 0.8, 1.6)
    b.add("low_wall", _box((-L / 2, 0.0, -0.3), (L / 2, h, 0.3)), "masonry")
    b.add("coping", _box((-L / 2 - 0.05, h, -0.35), (L / 2 + 0.05, h + 0.12, 0.35)), "trim")
    return L / 2, h + 0.12


def _tree(r: Rng) -> tuple[list[_Geom], list[_Geom], float, float]:
    """Trunk and crown geometry of one tree at the origin: (trunks, crowns, radius, height)."""
    kind = _pick(r, ("conifer", "deciduous", "deciduous", "poplar", "cluster"))
    h = _u(r, 4.0, 14.0)
    tr = _u(r, 0.12, 0.22) * (h / 8.0) ** 0.5
    if kind == "conifer":
        cr = h * _u(r, 0.18, 0.3)
        trunk = [_frustum(tr, 0.7 * tr, 0.0, 0.3 * h, 8)]
        layers = _ri(r, 1, 3)
        crowns = []
        for k in range(layers):
            y0 = h * (0.2 + 0.22 * k)
            rk = cr * (1.0 - 0.22 * k)
            crowns.append(_frustum(rk, 0.0, y0, min(h, y0 + h * (0.8 - 0.2 * k)), 12))
        return trunk, crowns, cr, h
    if kind == "poplar":
        cr = h * _u(r, 0.1, 0.16)
        trunk = [_frustum(tr, 0.7 * tr, 0.0, 0.35 * h, 8)]
        return trunk, [_ellipsoid((cr, 0.42 * h, cr), (0.0, 0.56 * h, 0.0), 8, 12)], cr, h
    cr = h * _u(r, 0.28, 0.4)
    ht = h - 1.6 * cr
    trunk = [_frustum(tr, 0.7 * tr, 0.0, ht + 0.3 * cr, 8)]
    if kind == "deciduous":
        return trunk, [_ellipsoid((cr, 0.8 * cr, cr), (0.0, h - 0.8 * cr, 0.0), 8, 14)], cr, h
    crowns = [_ellipsoid((0.75 * cr,) * 3, (0.0, h - 0.75 * cr, 0.0), 6, 10)]
    for k in range(_ri(r, 2, 3)):
        a = 2 * np.pi * (k / 3.0 + _u(r, 0.0, 0.2))
        c = (0.45 * cr * math.sin(a), h - 1.1 * cr, 0.45 * cr * math.cos(a))
        crowns.append(_ellipsoid((0.6 * cr,) * 3, c, 6, 10))
    return trunk, crowns, cr, h


# --------------------------------------------------------------------------------------
# Scene generation
# --------------------------------------------------------------------------------------


def _make_part(name: str, g: _Geom, material: Material, role: str) -> Part:
    uv = g.uv / material.tile_m
    mesh = trimesh.Trimesh(
        vertices=g.v,
        faces=g.f,
        vertex_normals=g.n,
        visual=trimesh.visual.TextureVisuals(uv=uv),
        process=False,
        validate=False,
    )
    return Part(name, mesh, material, role, g.solid)


def _glossy(material: Material, u: float, alpha: float, fraction: float) -> Material:
    """Swap a diffuse material for rough plastic (or rough metal for bronze) when ``u < fraction``."""
    if u >= fraction:
        return material
    kind = "roughconductor" if material.texture_kind == "bronze" else "roughplastic"
    return Material(kind, material.texture, alpha, material.texture_kind, material.tile_m, material.name)


def _footprint_radius(g: _Geom) -> float:
    return float(np.max(np.linalg.norm(g.v[:, [0, 2]], axis=1)))


def _free_spot(r: Rng, center: np.ndarray, yaw: float, half_angle: float, base: float, extra: tuple[float, float],
               radius: float, margin: float, occupied: list[tuple[float, float, float, float]]
               ) -> tuple[float, float] | None:
    """A ground point ``(x, z)`` around ``center``: direction ``yaw +- half_angle``, distance
    ``base + uniform(*extra)``, farther than ``radius + r_i + margin`` from every occupied
    circle ``(x_i, z_i, r_i, top)``; None after 20 tries."""
    for _ in range(20):
        a = yaw + r.uniform(-half_angle, half_angle)
        d = base + r.uniform(*extra)
        x, z = center[0] + d * math.sin(a), center[2] + d * math.cos(a)
        if all(math.hypot(x - ox, z - oz) > radius + orad + margin for ox, oz, orad, _ in occupied):
            return x, z
    return None


def generate_scene(
    seed: int,
    glossy_fraction: float = 0.0,
    trees: bool = True,
    *,
    landmark_type: str | None = None,
    texture_size: int = 256,
    ground_size: float = DEFAULT_GROUND_SIZE,
) -> SceneSpec:
    """A seeded outdoor scene: one landmark, 0-3 props, optional trees, textured ground.

    Args:
        seed: non-negative integer; the same arguments give the same bytes.
        glossy_fraction: in [0, 1]: probability that each landmark/prop material is
            non-Lambertian (rough plastic; rough conductor for bronze). Ground and trees
            stay diffuse. The geometry and textures do not depend on it.
        trees: add 0-9 trees around the landmark.
        landmark_type: force one of :data:`LANDMARK_TYPES` (default: drawn from the seed).
        texture_size: texture resolution S (textures are S x S).
        ground_size: side of the square ground in metres (see the module docstring).

    Returns:
        :class:`SceneSpec`.

    Raises:
        ValueError: bad arguments.
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    if not 0.0 <= float(glossy_fraction) <= 1.0:
        raise ValueError(f"glossy_fraction must lie in [0, 1], got {glossy_fraction}")
    if landmark_type is not None and landmark_type not in _BUILDERS:
        raise ValueError(f"landmark_type must be one of {LANDMARK_TYPES}, got {landmark_type!r}")
    if isinstance(texture_size, bool) or not isinstance(texture_size, (int, np.integer)) or texture_size < 8:
        raise ValueError(f"texture_size must be an integer >= 8, got {texture_size!r}")
    # Independent streams: switching trees off or changing glossy_fraction leaves the
    # landmark and its textures untouched.
    geo, tex, veg, gloss = (np.random.default_rng(s) for s in np.random.SeedSequence(int(seed)).spawn(4))
    drawn = LANDMARK_TYPES[int(geo.integers(len(LANDMARK_TYPES)))]
    ltype = landmark_type or drawn
    palette = _Palette(tex, int(texture_size))

    lb = _Builder(palette, "landmark")
    params = _BUILDERS[ltype](geo, lb)
    front_yaw = float(geo.uniform(-np.pi, np.pi))
    R = _ry(front_yaw)
    landmark = {k: _xf(g, R) for k, g in lb.merged().items()}
    all_v = np.concatenate([g.v for g in landmark.values()])
    bounds = np.stack([all_v.min(axis=0), all_v.max(axis=0)])
    if bounds[1, 0] - bounds[0, 0] < 1.0 or bounds[1, 1] < 1.0:
        raise RuntimeError(f"degenerate landmark {ltype} for seed {seed}")  # a generator bug, not bad input
    r_fp = max(_footprint_radius(g) for g in landmark.values())
    center = 0.5 * (bounds[0] + bounds[1])

    # Props: 0-3, mostly in front of the landmark (the plaza), not overlapping.
    occupied: list[tuple[float, float, float, float]] = []  # (x, z, radius, top)
    named: list[tuple[str, _Geom, str, str]] = [(k, g, lb.slots[k], "landmark") for k, g in landmark.items()]
    n_props = 0
    for _ in range(int(geo.integers(0, 4))):
        pb = _Builder(palette, f"prop{n_props}")
        rad, top = _build_prop(geo, pb)
        spot = _free_spot(geo, center, front_yaw, 1.6, r_fp + rad, (2.0, 10.0), rad, 1.0, occupied)
        if spot is None:
            continue
        x, z = spot
        yaw = float(geo.uniform(-np.pi, np.pi))
        occupied.append((x, z, rad, top))
        n_props += 1
        for k, g in pb.merged().items():
            named.append((k, _xf(g, _ry(yaw), (x, 0.0, z)), pb.slots[k], "prop"))

    n_trees = 0
    if trees:
        trunks, crowns = [], []
        for _ in range(int(veg.integers(0, 10))):
            tg, cg, cr, h = _tree(veg)
            spot = _free_spot(veg, center, 0.0, np.pi, r_fp + cr, (3.0, 35.0), cr, 0.5, occupied)
            if spot is None:
                continue
            x, z = spot
            occupied.append((x, z, cr, h))
            trunks += [_xf(g, None, (x, 0.0, z)) for g in tg]
            crowns += [_xf(g, None, (x, 0.0, z)) for g in cg]
            n_trees += 1
        if n_trees:
            palette.get("bark")
            palette.get("foliage")
            named.append(("trees_trunks", _cat(trunks), "bark", "tree"))
            named.append(("trees_crowns", _cat(crowns), "foliage", "tree"))

    gs = float(ground_size)
    if not gs > 4 * (r_fp + 40.0):
        raise ValueError(f"ground_size {gs} m is too small for this scene (needs > {4 * (r_fp + 40.0):.0f} m)")
    h = gs / 2
    ground = _Geom(
        np.array([[center[0] - h, 0.0, center[2] - h], [center[0] + h, 0.0, center[2] - h],
                  [center[0] + h, 0.0, center[2] + h], [center[0] - h, 0.0, center[2] + h]]),
        np.array([[0, 2, 1], [0, 3, 2]]),  # counter-clockwise seen from above (+y)
        np.zeros((4, 2)),
        np.tile([0.0, 1.0, 0.0], (4, 1)),
    )
    ground.uv = ground.v[:, [0, 2]].copy()
    palette.get("ground")
    named.append(("ground", ground, "ground", "ground"))

    # Non-Lambertian swap: one draw pair per material slot, whatever the fraction.
    materials: dict[str, Material] = {}
    for slot, mat in palette.mats.items():
        u, alpha = float(gloss.random()), float(gloss.uniform(0.05, 0.4))
        is_scene_solid = slot not in ("ground", "bark", "foliage")
        materials[slot] = _glossy(mat, u, alpha, float(glossy_fraction)) if is_scene_solid else mat

    parts = [_make_part(name, g, materials[slot], role) for name, g, slot, role in named]
    params = {k: (round(v, 4) if isinstance(v, float) else v) for k, v in params.items()}
    params["n_props"] = n_props
    params["n_trees"] = n_trees
    return SceneSpec(
        seed=int(seed),
        landmark_type=ltype,
        parts=parts,
        landmark_bounds=bounds,
        ground_size=gs,
        front_yaw=front_yaw,
        obstacles=np.asarray(occupied, dtype=np.float64).reshape(-1, 4),
        glossy_fraction=float(glossy_fraction),
        trees=bool(trees),
        params=params,
    )


# --------------------------------------------------------------------------------------
# Mitsuba
# --------------------------------------------------------------------------------------


def _bitmap(texture: np.ndarray, mi: ModuleType) -> dict[str, Any]:
    # raw=True: the texels are already linear reflectance, no sRGB decoding or spectral
    # upsampling; bilinear + repeat matches the tileable textures (texel-centred lookups).
    return {
        "type": "bitmap",
        "bitmap": mi.Bitmap(np.ascontiguousarray(texture, dtype=np.float32)),
        "raw": True,
        "filter_type": "bilinear",
        "wrap_mode": "repeat",
    }


def material_to_mitsuba(material: Material, mi: ModuleType) -> dict[str, Any]:
    """Mitsuba BSDF dict of a :class:`Material` (diffuse / roughplastic / roughconductor)."""
    tex = _bitmap(material.texture, mi)
    if material.kind == "diffuse":
        return {"type": "diffuse", "reflectance": tex}
    if material.kind == "roughplastic":
        return {"type": "roughplastic", "distribution": "ggx", "alpha": float(material.roughness),
                "int_ior": 1.5, "ext_ior": 1.0, "nonlinear": False, "diffuse_reflectance": tex}
    return {"type": "roughconductor", "distribution": "ggx", "alpha": float(material.roughness),
            "material": "none", "specular_reflectance": tex}


def to_mitsuba(spec: SceneSpec, mi: ModuleType) -> dict[str, Any]:
    """The shapes part of a Mitsuba scene dict: ``{part name: mi.Mesh}``.

    Meshes are built in memory (float32 positions, vertex normals, texcoords) with
    their BSDF attached; parts that share a :class:`Material` share one BSDF. Merge the
    result into a scene dict with an emitter and a sensor, e.g.
    ``mi.load_dict({"type": "scene", **to_mitsuba(spec, mi), "sky": ..., "sensor": ...})``.
    Build a fresh dict for every ``load_dict`` (Mitsuba objects belong to one scene).

    Args:
        spec: the scene.
        mi: the Mitsuba module from :func:`synth.backend.load_mitsuba`.
    """
    bsdfs: dict[int, Any] = {}
    shapes: dict[str, Any] = {}
    for part in spec.parts:
        if part.name in shapes or part.name in ("type", "integrator", "sensor"):
            raise ValueError(f"part name {part.name!r} is duplicated or reserved")
        key = id(part.material)
        if key not in bsdfs:
            bsdfs[key] = mi.load_dict(material_to_mitsuba(part.material, mi))
        props = mi.Properties()
        props["bsdf"] = bsdfs[key]
        m = part.mesh
        mesh = mi.Mesh(part.name, len(m.vertices), len(m.faces), props=props,
                       has_vertex_normals=True, has_vertex_texcoords=True)
        params = mi.traverse(mesh)
        params["vertex_positions"] = np.asarray(m.vertices, dtype=np.float32).ravel()
        params["faces"] = np.asarray(m.faces, dtype=np.uint32).ravel()
        params["vertex_normals"] = part.normals.astype(np.float32).ravel()
        params["vertex_texcoords"] = part.uv.astype(np.float32).ravel()
        params.update()
        shapes[part.name] = mesh
    return shapes
