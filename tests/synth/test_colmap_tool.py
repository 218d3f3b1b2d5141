"""The real COLMAP (Debian's 3.8) on a rendered multi-view set, read back by the library's reader.

A textured synth landmark is rendered from 24 views of a walk-around capture (photos and sky masks
in COLMAP's mask convention, black = sky), and COLMAP's CPU pipeline (``feature_extractor`` with
those masks and the lens's intrinsics, ``exhaustive_matcher``, ``mapper``) reconstructs it. The sparse
model it writes is read by :mod:`physrelight.colmap_format`; after a similarity alignment of the camera
centres (Umeyama) the registered cameras' rotations, converted into this library's frame, are compared
with the rendered cameras': every camera within 1 degree (the worst 0.53-0.77 deg in five runs at
768 px; at 384 px it was 1.0-2.3 deg, see docs/training-data.md). COLMAP's dense
stereo needs CUDA, so the depth reader is tested on maps written to the documented format
(``tests/physrelight/test_colmap_format.py``).

Slow (rendering and SfM: 4-7 minutes on 2 busy cores: render 90-150 s, COLMAP about 100 s a run on one thread,
a second run when the first misses the bar) and needs ``colmap`` on PATH:
``PHYSRELIGHT_COLMAP=1 bash scripts/setup.sh`` installs it (CI does).
"""

from __future__ import annotations

import shutil
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

pytestmark = [pytest.mark.slow, pytest.mark.colmap]

VIEWS = 24
RES = 768  # at 384 px SIFT's ~0.6 px residual is twice the angle, and the worst view missed 1 deg (1.0-2.3)
YAW = 30.0  # views within +-YAW degrees of the landmark's front
ELEVATED = 0.25  # share of views from above eye level (a height baseline as well as a horizontal one)
FOV = 55.0  # one calibrated lens: COLMAP is given its intrinsics and estimates the poses
SPP = 32
SCENE_SEED = 1  # a building with storeys, windows and wings: textured, and no symmetry that lets SIFT mix views up


def umeyama(src: np.ndarray, dst: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Similarity ``(s, R, t)`` minimising ``sum |dst - (s R src + t)|^2`` over ``src, dst (N, 3)``
    (Umeyama 1991: SVD of the cross-covariance, reflection excluded)."""
    mu_s, mu_d = src.mean(0), dst.mean(0)
    a, b = src - mu_s, dst - mu_d
    cov = b.T @ a / len(src)
    U, S, Vt = np.linalg.svd(cov)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = U @ D @ Vt
    s = float(np.trace(np.diag(S) @ D) / a.var(0).sum())
    return s, R, mu_d - s * R @ mu_s


def test_umeyama_recovers_a_known_similarity() -> None:
    rng = np.random.default_rng(0)
    src = rng.normal(size=(20, 3))
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    R = q * np.sign(np.linalg.det(q))
    dst = 2.5 * src @ R.T + np.array([1.0, -2.0, 0.5])
    s, R2, t = umeyama(src, dst)
    assert s == pytest.approx(2.5, rel=1e-12) and np.allclose(R2, R, atol=1e-12)
    assert np.allclose(t, [1.0, -2.0, 0.5], atol=1e-12)


def _colmap(*args: str, cwd: Path) -> None:
    out = subprocess.run(["colmap", *args], cwd=cwd, capture_output=True, text=True)
    assert out.returncode == 0, f"colmap {args[0]} failed:\n{out.stdout[-2000:]}\n{out.stderr[-2000:]}"


def rotation_angles_deg(R: np.ndarray) -> np.ndarray:
    """The angle of each rotation ``R (..., 3, 3)`` in degrees, ``(...)``."""
    return np.degrees(np.arccos(np.clip((np.trace(R, axis1=-2, axis2=-1) - 1) / 2, -1, 1)))


def reconstruct(ws: Path, work: Path, K: np.ndarray, max_error: float = 1.5, mapper_args: tuple[str, ...] = ()
                ) -> None:
    """COLMAP's CPU pipeline on the workspace ``ws`` (``images/``, ``masks/``) into ``work`` (``database.db``,
    ``sparse/``): SIFT with the sky masks and the lens ``K (3, 3)`` given, exhaustive matching with guided
    matching and ``max_error`` px inliers, the mapper with the intrinsics held. ``mapper_args`` are appended
    (COLMAP refuses an option given twice, so a ``--Mapper.ba_refine_focal_length`` there replaces ours)."""
    (work / "sparse").mkdir(parents=True)
    db = str(work / "database.db")
    # The masks keep SIFT off the sky, as COLMAP's mask convention says (black = no features).
    _colmap("feature_extractor", "--database_path", db, "--image_path", str(ws / "images"),
            "--ImageReader.mask_path", str(ws / "masks"), "--ImageReader.camera_model", "PINHOLE",
            "--ImageReader.single_camera", "1", "--ImageReader.camera_params",
            ",".join(repr(float(x)) for x in (K[0, 0], K[1, 1], K[0, 2], K[1, 2])),
            "--SiftExtraction.use_gpu", "0", "--SiftExtraction.num_threads", "1", cwd=work)
    # Tighter inlier thresholds than COLMAP's defaults (4 px): the paving and the windows repeat, and matches
    # wrong by a tile, kept as inliers, cost half a degree here (median 0.88 -> 0.62 deg on one capture).
    _colmap("exhaustive_matcher", "--database_path", db, "--SiftMatching.use_gpu", "0",
            "--SiftMatching.num_threads", "1", "--SiftMatching.guided_matching", "1",
            "--SiftMatching.max_error", repr(float(max_error)), cwd=work)
    focal = [] if "--Mapper.ba_refine_focal_length" in mapper_args else ["--Mapper.ba_refine_focal_length", "0"]
    # A global bundle adjustment after every registered view (ratios 1.01, COLMAP's defaults 1.1) against the drift
    # that bent whole reconstructions by a degree (six runs of the same photos: worst 0.66-0.96 deg with it).
    global_ba = [] if any(a.startswith("--Mapper.ba_global") for a in mapper_args) else [
        "--Mapper.ba_global_images_ratio", "1.01", "--Mapper.ba_global_points_ratio", "1.01",
        "--Mapper.ba_global_max_num_iterations", "100"]
    _colmap("mapper", "--database_path", db, "--image_path", str(ws / "images"),
            "--output_path", str(work / "sparse"), "--Mapper.num_threads", "1", *focal, *global_ba,
            "--Mapper.ba_refine_extra_params", "0", "--Mapper.filter_max_reproj_error", "2", *mapper_args, cwd=work)


def pose_errors(truth: np.ndarray, est: np.ndarray) -> dict:
    """Rotation errors in degrees of the estimated ``world_to_camera (N, 4, 4)`` against the true ones:
    ``angles (N,)`` after the similarity (Umeyama) alignment of the camera centres, ``oriented (N,)`` after the
    rotation that best aligns the orientations (chordal mean of ``R_est_i^T R_true_i``), ``pairwise (N, N)`` of
    every pair's relative rotation (no alignment); also ``centres (N,)``, the aligned centres' errors, ``spread``,
    the true centres' mean distance from their mean, and the alignment's rotation ``R (3, 3)``."""
    centre = lambda T: -np.einsum("nji,nj->ni", T[:, :3, :3], T[:, :3, 3])  # noqa: E731  (-R^T t)
    s, R, t = umeyama(centre(est), centre(truth))
    # x_true = s R x_est + t, so a camera's world_to_camera rotation maps as R_true = R_est R^T.
    angles = rotation_angles_deg(truth[:, :3, :3] @ (est[:, :3, :3] @ R.T).transpose(0, 2, 1))
    U, _, Vt = np.linalg.svd((est[:, :3, :3].transpose(0, 2, 1) @ truth[:, :3, :3]).sum(0))
    Rt = U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))]) @ Vt
    oriented = rotation_angles_deg(truth[:, :3, :3].transpose(0, 2, 1) @ est[:, :3, :3] @ Rt)
    pair = np.einsum("iab,jcb->ijac", truth[:, :3, :3], truth[:, :3, :3])
    pair_e = np.einsum("iab,jcb->ijac", est[:, :3, :3], est[:, :3, :3])
    pairwise = rotation_angles_deg(np.einsum("ijba,ijbc->ijac", pair, pair_e))
    return {"angles": angles, "oriented": oriented, "pairwise": pairwise, "R": R,
            "centres": np.linalg.norm(s * centre(est) @ R.T + t - centre(truth), axis=1),
            "spread": float(np.linalg.norm(centre(truth) - centre(truth).mean(0), axis=1).mean())}


def render_capture(root: Path, views: int = VIEWS, res: int = RES, seed: int = SCENE_SEED
                   ) -> tuple[list[np.ndarray], np.ndarray]:
    """A walk-around capture of one textured synth landmark as a COLMAP workspace's ``images/`` and
    ``masks/`` (black = sky); returns each view's ``world_to_camera`` and the lens's ``K (3, 3)``.

    The views come from the library's tourist sampler with a capture's spread (yaw within +-25 deg of
    the front, 2-3 landmark radii away, one lens range; the dataset default spreads photos round the
    whole landmark, too far apart for SIFT at these sizes), lit by one clear sky, path traced at 32 spp
    and written as 8-bit sRGB with an exposure that puts the 99th percentile at white."""
    from physrelight import colour, io
    from synth import cameras, lighting, render, scene

    spec = scene.generate_scene(seed)
    cams = cameras.sample_views(spec, views, seed=7, width=res, height=res, yaw_range_deg=YAW,
                                distance_range=(2.0, 3.0), fov_range=(FOV, FOV), elevated_fraction=ELEVATED)
    light = lighting.sunsky(7, elevation_deg=40.0, resolution=32)
    mscene = render.build_scene(spec, cams, light, spp=SPP, seed=7)
    (root / "images").mkdir(parents=True)
    (root / "masks").mkdir()
    poses = []
    for i, cam in enumerate(cams):
        radiance = render.render_radiance(mscene, i, SPP, 7 + i)
        sky = render.render_geometry(mscene, i, cam, 1, 7 + i).sky_mask
        gain = 1.0 / max(np.percentile(radiance, 99), 1e-6)
        photo = np.asarray(colour.linear_to_srgb(np.clip(radiance * gain, 0, 1)))
        io.write_png(root / "images" / f"v{i:02d}.png", photo)
        io.write_png(root / "masks" / f"v{i:02d}.png.png", np.where(sky, 0.0, 1.0))
        poses.append(np.asarray(cam.world_to_camera, dtype=np.float64))
    return poses, np.asarray(cams[0].K, dtype=np.float64)


def test_colmap_reconstruction_is_read_in_the_rendered_frame(tmp_path: Path) -> None:
    if shutil.which("colmap") is None:
        pytest.skip("colmap is not on PATH; install it with PHYSRELIGHT_COLMAP=1 bash scripts/setup.sh "
                    "(Debian: apt-get install colmap)")
    pytest.importorskip("mitsuba")
    from physrelight import colmap_format as cf
    from physrelight.collections.colmap import parse_workspace

    t0 = time.perf_counter()
    ws = tmp_path / "capture"
    poses, K = render_capture(ws)
    t_render = time.perf_counter() - t0
    # COLMAP 3.8's CPU matcher is not deterministic, even on one thread with a fixed --random_seed (the same
    # features gave 31720-31770 raw matches over four runs), and the mapper follows: the worst camera of one set of
    # photos ranged 0.60-1.20 deg over runs (3.37 once, with COLMAP's default global adjustments, under load). The
    # bar is kept; a run that misses it is rerun once from the features up, and both runs are printed.
    for attempt in range(2):
        work = tmp_path / f"sfm{attempt}"
        reconstruct(ws, work, K)
        folder = cf.find_sparse_model(work / "sparse")
        assert folder is not None, "mapper wrote no model"
        model = cf.read_model(folder)
        truth = np.stack([poses[int(im.name[1:3])] for im in model.images.values()])
        est = np.stack([cf.world_to_camera_from_colmap(im.qvec, im.tvec) for im in model.images.values()])
        worst = pose_errors(truth, est)["angles"].max() if len(est) >= 3 else np.inf
        print(f"\n[colmap] run {attempt + 1}: {len(est)} views, worst rotation error {worst:.3f} deg")
        if worst < 1.0:
            break
    t_colmap = time.perf_counter() - t0 - t_render

    # The reader reads COLMAP's own binary model, and its text export the same.
    (work / "txt").mkdir()
    _colmap("model_converter", "--input_path", str(folder), "--output_path", str(work / "txt"),
            "--output_type", "TXT", cwd=work)
    text = cf.read_model(work / "txt")
    assert {i.name: i.qvec.round(5).tolist() for i in text.images.values()} == {
        i.name: i.qvec.round(5).tolist() for i in model.images.values()}

    registered = len(est)
    assert registered >= 0.75 * VIEWS, f"COLMAP registered {registered} of {VIEWS} views"
    err = pose_errors(truth, est)
    angles, angles_o, angles_p, centres, R = err["angles"], err["oriented"], err["pairwise"], err["centres"], err["R"]
    print(f"\n[colmap] orientation-aligned: median {np.median(angles_o):.3f} max {angles_o.max():.3f} deg; "
          f"pairwise relative rotations: median {np.median(angles_p):.3f} max {angles_p.max():.3f} deg")
    print(f"\n[colmap] {registered}/{VIEWS} views registered, {len(model.points3D)} points; rotation error "
          f"median {np.median(angles):.3f} max {angles.max():.3f} deg; centre error median {np.median(centres):.4f} "
          f"(camera spread {err['spread']:.2f}); render {t_render:.1f} s, colmap {t_colmap:.1f} s")
    # Every camera within 1 deg after the similarity alignment of the centres (the bar); measured on one
    # capture over six runs of COLMAP: worst 0.66-0.96 deg, median 0.35-0.56 deg (docs/training-data.md).
    assert angles.max() < 1.0, f"rotation errors {np.round(angles, 3)} deg"
    # Without the frame conversion (COLMAP's OpenCV camera taken as this library's) the error is 180 deg.
    flipped = np.diag([1.0, -1.0, -1.0]) @ est[:, :3, :3]
    assert rotation_angles_deg(truth[:, :3, :3] @ (flipped @ R.T).transpose(0, 2, 1)).min() > 90

    # The workspace reader takes the model's poses; CPU COLMAP has no dense depth, so every photo counts as
    # one without depth, and the unregistered ones as without a pose.
    shutil.copytree(folder, ws / "sparse" / "0")
    rec = parse_workspace(ws, "capture")
    assert rec.photos == [] and rec.skipped == {"no pose": VIEWS - registered, "no depth": registered}
