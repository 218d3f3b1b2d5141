"""The shapes part of a Mitsuba scene dict from a :class:`SceneSpec` (in-memory meshes, raw bitmap albedo)."""

from __future__ import annotations

from types import ModuleType
from typing import Any

import numpy as np

from .description import Material, SceneSpec

__all__ = ["material_to_mitsuba", "to_mitsuba"]


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
