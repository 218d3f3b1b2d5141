"""The scene description: :class:`Material`, :class:`Part`, :class:`SceneSpec` and the names they take."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import trimesh

__all__ = ["DEFAULT_GROUND_SIZE", "LANDMARK_TYPES", "MATERIAL_KINDS", "Material", "Part", "ROLES", "SceneSpec",
           "closed_solids"]


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
