""":func:`generate_scene`: a landmark, props, trees and the ground placed into one seeded :class:`SceneSpec`."""

from __future__ import annotations

import math

import numpy as np
import trimesh

from .description import DEFAULT_GROUND_SIZE, LANDMARK_TYPES, Material, Part, SceneSpec
from .geometry import _cat, _Geom, _ry, _xf
from .materials import _glossy, _Palette, Rng
from .landmarks import _build_prop, _Builder, _BUILDERS, _tree

__all__ = ["generate_scene"]


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
