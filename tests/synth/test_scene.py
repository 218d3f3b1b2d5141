"""Specification of synth.textures and synth.scene: seeded procedural landmarks whose
meshes are valid closed solids on the ground, whose albedo textures stay in the physical
range, and whose Mitsuba version reports exactly the texture as its albedo."""

from __future__ import annotations

import json
import time

import drjit as dr
import numpy as np
import pytest

from synth import cameras as C
from synth import scene as S
from synth import textures as T
from synth.backend import load_mitsuba

mi = load_mitsuba()
VECTOR = not mi.variant().startswith("scalar")
needs_vector = pytest.mark.skipif(not VECTOR, reason="array ray queries need Mitsuba's llvm variant")


class _AlbedoProbe(mi.SamplingIntegrator):
    """Albedo (``eval_diffuse_reflectance``) as the colour; ray direction and hit UV as AOVs."""

    def __init__(self, props):
        super().__init__(props)

    def sample(self, scene, sampler, ray, medium=None, active=True):
        si = scene.ray_intersect(ray, active)
        ok = si.is_valid()
        albedo = si.bsdf(ray).eval_diffuse_reflectance(si, ok)
        return mi.Spectrum(dr.select(ok, albedo, 0.0)), ok, [ray.d.x, ray.d.y, ray.d.z, si.uv.x, si.uv.y]

    def aov_names(self):
        return ["dx", "dy", "dz", "u", "v"]


mi.register_integrator("physrelight_test_scene_albedo", lambda props: _AlbedoProbe(props))


def bilinear(texture: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Mitsuba's bitmap lookup, repeat wrap: texel (i, j) centred at ((j + .5) / S, (i + .5) / S)."""
    s = texture.shape[0]
    x, y = uv[:, 0] * s - 0.5, uv[:, 1] * s - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    x0, y0 = x0.astype(np.int64) % s, y0.astype(np.int64) % s
    x1, y1 = (x0 + 1) % s, (y0 + 1) % s
    t = texture.astype(np.float64)
    return (t[y0, x0] * (1 - fx) * (1 - fy) + t[y0, x1] * fx * (1 - fy)
            + t[y1, x0] * (1 - fx) * fy + t[y1, x1] * fx * fy)


@pytest.fixture(scope="module")
def scenes() -> dict[str, S.SceneSpec]:
    """One scene per landmark type (seed 5), built once for the module."""
    return {t: S.generate_scene(5, landmark_type=t) for t in S.LANDMARK_TYPES}


# --------------------------------------------------------------------------------------
# Textures
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("kind", sorted(T.TEXTURES))
def test_01_textures_are_float32_linear_albedo_in_the_physical_range(kind):
    for seed in (0, 1):
        tex = T.random_material_texture(np.random.default_rng(seed), kind, 64)
        assert tex.dtype == np.float32 and tex.shape == (64, 64, 3)
        assert tex.min() >= T.ALBEDO_MIN and tex.max() <= T.ALBEDO_MAX
        assert tex.std() > 1e-3, "a texture must vary spatially"


@pytest.mark.parametrize("kind", sorted(T.TEXTURES))
def test_02_textures_tile_without_seams_and_repeat_from_the_same_generator_state(kind):
    tex = T.random_material_texture(np.random.default_rng(3), kind, 128).astype(np.float64)
    for axis in (0, 1):
        # Mean jump between neighbouring rows (columns): the wrap-around jump must look
        # like one of the texture's own (a mortar edge may sit on the seam, a cut may not).
        steps = np.abs(np.diff(tex, axis=axis)).mean(axis=(1 - axis, 2))
        seam = np.abs(np.take(tex, 0, axis=axis) - np.take(tex, -1, axis=axis)).mean()
        assert seam <= steps.max() + 1e-6, f"axis {axis}: seam {seam:.4f} vs largest step {steps.max():.4f}"
    again = T.random_material_texture(np.random.default_rng(3), kind, 128)
    assert again.tobytes() == tex.astype(np.float32).tobytes()


def test_03_value_noise_and_fbm_are_periodic_and_normalised():
    rng = np.random.default_rng(0)
    n = T.value_noise(rng, 64, 5)
    assert n.min() >= 0.0 and n.max() <= 1.0
    f = T.fbm(rng, 64, period=4, octaves=4)
    assert abs(f.mean()) < 1e-9 and np.abs(f).max() < 1.5
    with pytest.raises(ValueError, match="unknown texture kind"):
        T.random_material_texture(rng, "chrome", 64)
    with pytest.raises(ValueError, match="size"):
        T.stone(rng, 4)


# --------------------------------------------------------------------------------------
# Scenes
# --------------------------------------------------------------------------------------


def _part_bytes(spec: S.SceneSpec) -> list[bytes]:
    out = []
    for p in spec.parts:
        m = p.mesh
        out += [p.name.encode(), np.asarray(m.vertices).tobytes(), np.asarray(m.faces).tobytes(),
                p.uv.tobytes(), p.normals.tobytes(), p.material.texture.tobytes(), p.material.kind.encode()]
    return out


def test_04_same_seed_gives_identical_bytes_and_different_seeds_differ():
    a, b = S.generate_scene(11), S.generate_scene(11)
    assert _part_bytes(a) == _part_bytes(b)
    assert json.dumps(a.describe()) == json.dumps(b.describe())
    assert _part_bytes(S.generate_scene(12)) != _part_bytes(a)


def test_05_twenty_seeds_give_many_landmark_types_and_shapes():
    specs = [S.generate_scene(s, trees=False, texture_size=16) for s in range(20)]
    types = {s.landmark_type for s in specs}
    assert len(types) >= 7, f"only {sorted(types)} in 20 seeds"
    # Within a type the proportions differ too: no two landmarks share their bounds.
    sizes = {tuple(np.round(s.landmark_bounds[1] - s.landmark_bounds[0], 2)) for s in specs}
    assert len(sizes) == 20


@pytest.mark.parametrize("ltype", S.LANDMARK_TYPES)
def test_06_every_landmark_type_gives_valid_closed_meshes_standing_on_the_ground(scenes, ltype):
    spec = scenes[ltype]
    assert spec.landmark_type == ltype
    names = [p.name for p in spec.parts]
    assert len(set(names)) == len(names)
    assert [p.role for p in spec.parts].count("ground") == 1
    landmark_v = []
    for p in spec.parts:
        v, f = np.asarray(p.mesh.vertices), np.asarray(p.mesh.faces)
        assert np.isfinite(v).all() and np.isfinite(p.uv).all(), p.name
        assert p.uv.shape == (len(v), 2)
        assert np.abs(np.linalg.norm(p.normals, axis=1) - 1.0).max() < 1e-6, p.name
        assert p.mesh.area_faces.min() > 1e-6, f"{p.name}: degenerate face"
        # Shading normals agree with the winding (flat parts: exactly the face normal).
        dots = np.einsum("ij,ij->i", p.mesh.face_normals, p.normals[f].mean(axis=1))
        assert dots.min() > 0.3, f"{p.name}: vertex normals disagree with the faces"
        tex = p.material.texture
        assert tex.dtype == np.float32 and tex.min() >= T.ALBEDO_MIN and tex.max() <= T.ALBEDO_MAX
        if p.role == "ground":
            assert np.allclose(v[:, 1], 0.0) and np.all(p.mesh.face_normals[:, 1] > 0.999)
            continue
        assert v[:, 1].min() >= -1e-9, f"{p.name} goes below the ground"
        for solid in S.closed_solids(p):
            assert solid.is_watertight and solid.is_winding_consistent, p.name
            assert solid.volume > 0.0, f"{p.name}: normals point inwards"
        if p.role == "landmark":
            landmark_v.append(v)
    lv = np.concatenate(landmark_v)
    assert abs(lv[:, 1].min()) < 1e-9, "the landmark must stand on the ground (min y = 0)"
    np.testing.assert_allclose(spec.landmark_bounds, np.stack([lv.min(0), lv.max(0)]))
    assert spec.landmark_radius > 2.0


def test_07_glossy_fraction_swaps_landmark_materials_only_and_keeps_geometry():
    base = S.generate_scene(8, glossy_fraction=0.0)
    full = S.generate_scene(8, glossy_fraction=1.0)
    assert all(p.material.kind == "diffuse" for p in base.parts)
    for p, q in zip(base.parts, full.parts):
        assert np.asarray(p.mesh.vertices).tobytes() == np.asarray(q.mesh.vertices).tobytes()
        assert p.material.texture.tobytes() == q.material.texture.tobytes()
        if p.role in ("landmark", "prop"):
            assert q.material.kind in ("roughplastic", "roughconductor")
            assert 0.0 < q.material.roughness <= 1.0
        else:
            assert q.material.kind == "diffuse"
    kinds = [p.material.kind for s in range(20) for p in S.generate_scene(s, 0.5, texture_size=16).parts
             if p.role == "landmark"]
    glossy = np.mean([k != "diffuse" for k in kinds])
    assert 0.2 < glossy < 0.8


def test_08_trees_are_optional_and_do_not_change_the_landmark():
    with_trees = [S.generate_scene(s, texture_size=16) for s in range(6)]
    assert any(p.role == "tree" for s in with_trees for p in s.parts)
    for s, spec in enumerate(with_trees):
        bare = S.generate_scene(s, trees=False, texture_size=16)
        assert not any(p.role == "tree" for p in bare.parts)
        a = [np.asarray(p.mesh.vertices).tobytes() for p in spec.parts if p.role == "landmark"]
        b = [np.asarray(p.mesh.vertices).tobytes() for p in bare.parts if p.role == "landmark"]
        assert a == b


def test_09_describe_is_json_serialisable_and_names_parts_and_materials(scenes):
    d = json.loads(json.dumps(scenes["temple"].describe()))
    assert d["landmark_type"] == "temple" and d["seed"] == 5
    assert [p["name"] for p in d["parts"]] == [p.name for p in scenes["temple"].parts]
    assert {"kind", "texture_kind", "mean_albedo", "roughness"} <= set(d["parts"][0]["material"])
    assert np.array(d["landmark_bounds"]).shape == (2, 3)


def test_10_bad_arguments_raise_value_error():
    with pytest.raises(ValueError, match="seed"):
        S.generate_scene(-1)
    with pytest.raises(ValueError, match="glossy_fraction"):
        S.generate_scene(0, glossy_fraction=1.5)
    with pytest.raises(ValueError, match="landmark_type"):
        S.generate_scene(0, landmark_type="castle")
    with pytest.raises(ValueError, match="ground_size"):
        S.generate_scene(0, ground_size=50.0)
    tex = np.full((4, 4, 3), 0.5, np.float32)
    with pytest.raises(ValueError, match="kind"):
        S.Material("lambert", tex)
    with pytest.raises(ValueError, match="float32"):
        S.Material("diffuse", tex.astype(np.float64))
    with pytest.raises(ValueError, match="within"):
        S.Material("diffuse", tex * 3)
    with pytest.raises(ValueError, match="roughness"):
        S.Material("roughplastic", tex, roughness=0.0)


# --------------------------------------------------------------------------------------
# Mitsuba
# --------------------------------------------------------------------------------------


def test_11_to_mitsuba_loads_with_an_emitter_and_a_sensor_and_renders(scenes):
    spec = scenes["arch"]
    cam = C.sample_views(spec, 1, seed=0, width=24, height=16)[0]
    shapes = S.to_mitsuba(spec, mi)
    assert set(shapes) == {p.name for p in spec.parts}
    scene = mi.load_dict({"type": "scene", **shapes, "sky": {"type": "constant", "radiance": 1.0},
                          "sensor": C.to_mitsuba_sensor(cam, 4, mi), "integrator": {"type": "path", "max_depth": 3}})
    assert len(scene.shapes()) == len(spec.parts)
    img = np.asarray(mi.render(scene))
    assert img.shape == (16, 24, 3) and np.isfinite(img).all() and img.min() >= 0.0
    # Under a white constant sky, sky pixels are 1 and a surface of albedo < 0.85 is darker.
    assert img.max() <= 1.0 + 1e-5 and img.min() < 0.85


@needs_vector
@pytest.mark.parametrize("seed, glossy", [(3, 0.0), (11, 0.0), (29, 1.0)])
def test_12_mitsuba_albedo_equals_the_texture_looked_up_at_the_hit_uv(seed, glossy):
    spec = S.generate_scene(seed, glossy_fraction=glossy)
    cam = C.sample_views(spec, 1, seed=2, width=48, height=36)[0]
    scene = mi.load_dict({"type": "scene", **S.to_mitsuba(spec, mi),
                          "sensor": C.to_mitsuba_sensor(cam, 1, mi, seed=5),
                          "integrator": {"type": "physrelight_test_scene_albedo"}})
    # 1 spp + box filter: every pixel holds exactly one sample (albedo, direction, uv).
    img = np.asarray(mi.render(scene)).reshape(-1, 8)
    eye = cam.center.numpy()
    _, part = C.cast_rays(spec, np.tile(eye, (len(img), 1)), img[:, 3:6])
    checked = 0
    for k, p in enumerate(spec.parts):
        hit = part == k
        if not hit.any() or p.material.kind == "roughconductor":
            continue  # a conductor's eval_diffuse_reflectance is not an albedo
        want = bilinear(p.material.texture, img[hit, 6:8])
        np.testing.assert_allclose(img[hit, :3], want, atol=2e-6, err_msg=p.name)
        checked += int(hit.sum())
    assert checked > 0.3 * len(img)
    np.testing.assert_array_equal(img[part < 0, :3], 0.0)  # sky


def test_13_a_flat_coloured_texture_renders_exactly_its_colour():
    colour = np.array([0.2, 0.5, 0.7], np.float32)
    mat = S.Material("diffuse", np.tile(colour, (8, 8, 1)), texture_kind="flat", tile_m=1.0, name="flat")
    spec = S.generate_scene(0, trees=False, texture_size=16, landmark_type="monument")
    spec.parts = [S.Part(p.name, p.mesh, mat, p.role, p.solid_ids) for p in spec.parts]
    cam = C.sample_views(spec, 1, seed=0, width=20, height=16)[0]
    scene = mi.load_dict({"type": "scene", **S.to_mitsuba(spec, mi), "sensor": C.to_mitsuba_sensor(cam, 1, mi),
                          "integrator": {"type": "physrelight_test_scene_albedo"}})
    img = np.asarray(mi.render(scene))[..., :3].reshape(-1, 3)  # 1 spp: no partly covered pixels
    surface = img.sum(axis=1) > 0
    assert surface.mean() > 0.3
    # Raw float texels: no sRGB decoding, no spectral round trip, exact to float32.
    np.testing.assert_allclose(img[surface], np.broadcast_to(colour, img[surface].shape), rtol=0, atol=1e-6)


def test_14_generate_to_mitsuba_and_load_take_well_under_a_second():
    times = []
    for seed in range(4):
        t0 = time.perf_counter()
        spec = S.generate_scene(100 + seed)
        mi.load_dict({"type": "scene", **S.to_mitsuba(spec, mi), "sky": {"type": "constant"}})
        times.append(time.perf_counter() - t0)
    assert np.median(times) < 1.0, f"generate + to_mitsuba + load_dict took {times}"
