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

Modules: :mod:`.description` (:class:`Material`, :class:`Part`, :class:`SceneSpec`), :mod:`.geometry` (the
primitives), :mod:`.materials` (slots and palette), :mod:`.landmarks` (the ten types, props, trees),
:mod:`.generate` (:func:`generate_scene`), :mod:`.mitsuba_dict` (:func:`to_mitsuba`); every public name is
importable from ``synth.scene``.
"""

from __future__ import annotations

from .description import (DEFAULT_GROUND_SIZE, LANDMARK_TYPES, MATERIAL_KINDS, ROLES, Material, Part, SceneSpec,
                          closed_solids)
from .generate import generate_scene
from .mitsuba_dict import material_to_mitsuba, to_mitsuba

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
