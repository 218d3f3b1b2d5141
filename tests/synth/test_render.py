"""Specification of synth.render: the ground-truth buffers obey the conventions and the physics.

Tiny renders (32-48 px, few spp) of hand-made scenes with known geometry and albedo.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from physrelight import camera as pcam
from synth import cameras, lighting, render
from validation.scenes import box_spec, sphere_spec, view


@pytest.fixture(scope="module")
def sky_light() -> lighting.Lighting:
    return lighting.sunsky(3, elevation_deg=40.0, azimuth_deg=30.0, turbidity=3.0, resolution=64)


@pytest.fixture(scope="module")
def sphere_render(sky_light):
    spec = sphere_spec()
    cam = view([0.3, 1.6, 4.0], [0, 1.5, 0])
    scene = render.build_scene(spec, [cam], sky_light, spp=32, max_depth=2)
    geo = render.render_geometry(scene, 0, cam, spp=8, seed=1)
    return spec, cam, scene, geo


def test_01_sky_mask_is_where_no_surface_is(sphere_render, sky_light) -> None:
    spec, cam, scene, geo = sphere_render
    o, d = cameras.camera_rays(cam)
    t, _ = cameras.cast_rays(spec, o, d)
    np.testing.assert_array_equal(geo.sky_mask.ravel(), ~np.isfinite(t))
    assert geo.sky_mask.any() and (~geo.sky_mask).any()
    sky = geo.sky_mask
    assert np.all(geo.depth[sky] == 0) and np.all(geo.normal[sky] == 0) and np.all(geo.albedo[sky] == 0)
    # On sky pixels the radiance is the environment averaged over the pixel's rays
    # (8 x 8 sub-pixel rays give the expectation of the box-filtered film). Per-pixel
    # z-test against the spread of 6 independent renders (the horizon, where the sunsky
    # drops to black, makes some pixels noisy).
    from scipy import ndimage

    from physrelight import envmap
    inner = ~ndimage.binary_dilation(~sky)  # away from silhouettes (coverage is itself sampled)
    runs = np.stack([render.render_lit(scene, 0, sky_light, spp=64, shadow_spp=1, seed=10 + k).radiance[inner]
                     for k in range(6)])
    h, w = sky.shape
    _, fine = cameras.camera_rays(cam, 8 * w, 8 * h)
    expect = envmap.sample(sky_light.sky, fine).reshape(h, 8, w, 8, 3).mean(axis=(1, 3))[inner]
    mean, sem = runs.mean(0), runs.std(0, ddof=1) / math.sqrt(len(runs))
    z = (mean - expect) / np.maximum(sem, 1e-3 * expect + 1e-6)
    assert abs(mean.sum() / expect.sum() - 1) < 2e-3
    assert np.mean(np.abs(z) > 4) < 0.01


def test_02_normals_are_unit_and_face_the_camera(sphere_render) -> None:
    _, cam, _, geo = sphere_render
    surf = ~geo.sky_mask
    np.testing.assert_allclose(np.linalg.norm(geo.normal[surf], axis=-1), 1.0, atol=1e-5)
    pts = pcam.backproject(torch.from_numpy(geo.depth)[None, None], torch.as_tensor(cam.K, dtype=torch.float32))
    p = pts[0].permute(1, 2, 0).numpy()[surf]
    assert np.all(np.sum(geo.normal[surf] * -p, axis=-1) > 0)


def test_03_depth_back_projects_onto_the_surface(sphere_render) -> None:
    spec, cam, _, geo = sphere_render
    surf = ~geo.sky_mask
    pts = pcam.backproject(torch.from_numpy(geo.depth)[None, None].double(), torch.as_tensor(cam.K, dtype=torch.float64))
    p_cam = pts[0].permute(1, 2, 0).numpy()[surf]
    T = np.asarray(cam.world_to_camera, dtype=np.float64)
    p_world = (p_cam - T[:3, 3]) @ T[:3, :3]
    # On the sphere of radius 1 centred at (0, 1.5, 0) up to the tessellation (level 5).
    r = np.linalg.norm(p_world - [0, 1.5, 0], axis=-1)
    assert np.abs(r - 1.0).max() < 2e-3
    # And the normals are the sphere's radial directions, rotated into the camera frame.
    radial_cam = ((p_world - [0, 1.5, 0]) / r[:, None]) @ T[:3, :3].T
    angle = np.degrees(np.arccos(np.clip(np.sum(radial_cam * geo.normal[surf], -1), -1, 1)))
    assert angle.max() < 1.0


def test_04_albedo_file_equals_the_assigned_texture(sphere_render) -> None:
    _, _, _, geo = sphere_render
    full = geo.coverage == 1
    np.testing.assert_allclose(geo.albedo[full], np.broadcast_to([0.6, 0.45, 0.3], geo.albedo[full].shape), atol=1e-6)


def test_05_unoccluded_diffuse_radiance_is_albedo_times_irradiance_over_pi(sphere_render, sky_light) -> None:
    # A convex object alone (no ground): direct light only, no interreflection. Per-pixel
    # z-test with the sample variance over independent seeds; only pixels wholly on the
    # sphere and away from the sun terminator (the pixel footprint straddles it there).
    _, cam, scene, geo = sphere_render
    runs = np.stack([render.render_lit(scene, 0, sky_light, spp=32, shadow_spp=1, seed=100 + k).radiance
                     for k in range(8)])
    mean, sem = runs.mean(0), runs.std(0, ddof=1) / math.sqrt(len(runs))
    T = np.asarray(cam.world_to_camera, dtype=np.float64)
    n_world = geo.normal.reshape(-1, 3).astype(np.float64) @ T[:3, :3]
    ok = (geo.coverage.ravel() == 1) & (np.abs(n_world @ sky_light.sun_direction) > 0.15)
    exact = np.zeros((n_world.shape[0], 3))
    exact[ok] = np.asarray([0.6, 0.45, 0.3]) * sky_light.irradiance_reference(n_world[ok]) / math.pi
    m, s, e = mean.reshape(-1, 3)[ok], sem.reshape(-1, 3)[ok], exact[ok]
    ratio = m.sum() / e.sum()
    assert abs(ratio - 1) < 0.01, ratio
    z = (m - e) / np.maximum(s, 1e-3 * e)
    # Shading normals vs the tessellated surface and pixel-footprint averaging add a
    # small bias; allow |z| > 4 in at most 2 % of the channels.
    assert np.mean(np.abs(z) > 4) < 0.02, np.mean(np.abs(z) > 4)


def test_06_a_box_under_a_low_sun_casts_its_shadow_away_from_the_sun() -> None:
    light = lighting.evening(0, elevation_deg=15.0, azimuth_deg=90.0, resolution=32)  # sun towards +X
    spec = box_spec()
    cam = view([0.0, 12.0, 0.01], [0.0, 0.0, 0.0], size=48, fov=60)  # looking down
    scene = render.build_scene(spec, [cam], light, spp=4)
    geo = render.render_geometry(scene, 0, cam, spp=4, seed=0)
    lit = render.render_lit(scene, 0, light, spp=4, shadow_spp=16, seed=0)
    pts = pcam.backproject(torch.from_numpy(geo.depth)[None, None].double(), torch.as_tensor(cam.K, dtype=torch.float64))
    T = np.asarray(cam.world_to_camera, dtype=np.float64)
    p_world = (pts[0].permute(1, 2, 0).numpy() - T[:3, 3]) @ T[:3, :3]
    on_ground = (np.abs(p_world[..., 1]) < 1e-3) & ~geo.sky_mask
    shadowed = on_ground & (lit.shadow < 0.5)
    assert shadowed.sum() > 20
    xs = p_world[shadowed][:, 0]
    # Shadow on the -X side, reaching about h / tan(15 deg) = 7.5 m from the box.
    assert np.all(xs < 0.5) and xs.min() < -4.0
    assert np.all(lit.shadow[on_ground & (p_world[..., 0] > 1.0)] > 0.99)
    # Without shadow, shadow == sun visibility; direct ratio dips there too.
    np.testing.assert_array_equal(lit.shadow, lit.sun_visibility)
    assert lit.direct_shadow[shadowed].mean() < lit.direct_shadow[on_ground & ~shadowed].mean()


def test_07_warping_view_a_into_b_reproduces_b_albedo_where_both_see(sky_light) -> None:
    from synth.scene import generate_scene

    spec = generate_scene(4)
    a_view = cameras.sample_views(spec, 1, seed=3, width=48, height=48)[0]
    eye = np.linalg.inv(np.asarray(a_view.world_to_camera, dtype=np.float64))[:3, 3]
    target = spec.landmark_center
    side = np.cross(target - eye, [0.0, 1.0, 0.0])
    eye_b = eye + 0.15 * spec.landmark_radius * side / np.linalg.norm(side) + [0.0, 0.5, 0.0]
    views = [a_view, pcam.Camera.look_at(eye_b, target, 55.0, 48, 48)]
    scene = render.build_scene(spec, views, sky_light, spp=4)
    a = render.render_geometry(scene, 0, views[0], spp=16, seed=0)
    b = render.render_geometry(scene, 1, views[1], spp=16, seed=0)
    t = lambda x: torch.from_numpy(np.ascontiguousarray(x)).double()  # noqa: E731
    img_a = t(a.albedo).permute(2, 0, 1)[None]
    rel = pcam.relative_pose(t(views[1].world_to_camera), t(views[0].world_to_camera))  # B -> A
    warped, valid = pcam.warp(img_a, t(b.depth)[None, None], t(views[1].K), t(views[0].K), rel,
                              depth_src=t(a.depth)[None, None])
    valid = valid[0, 0].numpy() & (b.coverage == 1)
    assert valid.mean() > 0.3
    err = np.abs(warped[0].permute(1, 2, 0).numpy() - b.albedo)[valid].max(axis=-1)
    # Textures are resampled at a different scale in each view: bounded, not exact.
    assert np.median(err) < 0.03 and np.mean(err < 0.1) > 0.9
