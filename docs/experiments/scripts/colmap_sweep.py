"""COLMAP 3.8's pose accuracy on a rendered walk-around capture, per setting (docs/training-data.md's table).

Renders the capture of tests/synth/test_colmap_tool.py once per (resolution, views, lens, spp, distance, yaw,
scene) under --out, reruns COLMAP's CPU pipeline --reps times on the same photos (it is not deterministic), and
prints per run: views registered, points, rotation error after the centres' similarity alignment (median, max),
the alignment-free pairwise relative rotations, after an orientation alignment, and the mean reprojection error.
Example: python docs/experiments/scripts/colmap_sweep.py --res 768 --reps 3
"""
import sys, os, shutil, subprocess, time, json, argparse
from pathlib import Path
import numpy as np
ROOT = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(ROOT)); sys.path.insert(0, str(ROOT / "tests" / "synth"))
import test_colmap_tool as T
from physrelight import colmap_format as cf

ap = argparse.ArgumentParser()
ap.add_argument("--res", type=int, default=384); ap.add_argument("--views", type=int, default=24)
ap.add_argument("--fov", type=float, default=55.0); ap.add_argument("--spp", type=int, default=32)
ap.add_argument("--dist", type=str, default="2,3"); ap.add_argument("--yaw", type=float, default=30)
ap.add_argument("--seed", type=int, default=1)
ap.add_argument("--maxerr", type=float, default=1.5); ap.add_argument("--ba", type=int, default=0)
ap.add_argument("--reps", type=int, default=1); ap.add_argument("--tag", default="a")
ap.add_argument("--extra", default="")
ap.add_argument("--out", default="colmap_sweep")
a = ap.parse_args()
root = Path(a.out) / (f"cap_{a.res}_{a.views}_{a.fov}_{a.spp}_{a.dist}_{a.yaw}_{a.seed}")
if not (root / "poses.npy").exists():
    shutil.rmtree(root, ignore_errors=True)
    import synth.cameras as C
    orig = C.sample_views
    d0, d1 = map(float, a.dist.split(","))
    def sv(spec, n, seed, width, height, **kw):
        kw["distance_range"] = (d0, d1); kw["yaw_range_deg"] = a.yaw; kw["fov_range"] = (a.fov, a.fov)
        return orig(spec, n, seed=seed, width=width, height=height, **kw)
    C.sample_views = sv
    T.SPP = a.spp
    t = time.time()
    poses, K = T.render_capture(root, views=a.views, res=a.res, seed=a.seed)
    np.save(root / "poses.npy", np.stack(poses)); np.save(root / "K.npy", K)
    print("render", time.time() - t)
poses = np.load(root / "poses.npy"); K = np.load(root / "K.npy")
def col(*args, cwd):
    out = subprocess.run(["colmap", *args], cwd=cwd, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout
for rep in range(a.reps):
    work = root / f"sfm_{a.tag}_{rep}"
    shutil.rmtree(work, ignore_errors=True); (work / "sparse").mkdir(parents=True)
    db = str(work / "database.db"); t = time.time()
    col("feature_extractor", "--database_path", db, "--image_path", str(root / "images"),
        "--ImageReader.mask_path", str(root / "masks"), "--ImageReader.camera_model", "PINHOLE",
        "--ImageReader.single_camera", "1", "--ImageReader.camera_params",
        ",".join(repr(float(x)) for x in (K[0, 0], K[1, 1], K[0, 2], K[1, 2])),
        "--SiftExtraction.use_gpu", "0", "--SiftExtraction.num_threads", "2", cwd=work)
    col("exhaustive_matcher", "--database_path", db, "--SiftMatching.use_gpu", "0",
        "--SiftMatching.num_threads", "2", "--SiftMatching.guided_matching", "1", "--SiftMatching.max_error", str(a.maxerr), cwd=work)
    extra = a.extra.split() if a.extra else []
    col("mapper", "--database_path", db, "--image_path", str(root / "images"),
        "--output_path", str(work / "sparse"), "--Mapper.num_threads", "2", *([] if "focal" in a.extra else ["--Mapper.ba_refine_focal_length", "0"]),
        "--Mapper.ba_refine_extra_params", "0", "--Mapper.filter_max_reproj_error", "2", *extra, cwd=work)
    folder = cf.find_sparse_model(work / "sparse")
    if a.ba:
        (work / "ba").mkdir()
        col("bundle_adjuster", "--input_path", str(folder), "--output_path", str(work / "ba"),
            "--BundleAdjustment.max_num_iterations", "500", "--BundleAdjustment.refine_focal_length", "0",
            "--BundleAdjustment.refine_principal_point", "0", "--BundleAdjustment.refine_extra_params", "0",
            "--BundleAdjustment.function_tolerance", "1e-10", "--BundleAdjustment.gradient_tolerance", "1e-12", "--BundleAdjustment.parameter_tolerance", "1e-10", cwd=work)
        folder = work / "ba"
    tc = time.time() - t
    model = cf.read_model(folder)
    truth = np.stack([poses[int(im.name[1:3])] for im in model.images.values()])
    est = np.stack([cf.world_to_camera_from_colmap(im.qvec, im.tvec) for im in model.images.values()])
    centre = lambda T_: -np.einsum("nji,nj->ni", T_[:, :3, :3], T_[:, :3, 3])
    s, R, t_ = T.umeyama(centre(est), centre(truth))
    rel = truth[:, :3, :3] @ (est[:, :3, :3] @ R.T).transpose(0, 2, 1)
    ang = np.degrees(np.arccos(np.clip((np.trace(rel, axis1=1, axis2=2) - 1) / 2, -1, 1)))
    pair = np.einsum("iab,jcb->ijac", truth[:, :3, :3], truth[:, :3, :3])
    pair_e = np.einsum("iab,jcb->ijac", est[:, :3, :3], est[:, :3, :3])
    rp = np.einsum("ijba,ijbc->ijac", pair, pair_e)
    angp = np.degrees(np.arccos(np.clip((np.trace(rp, axis1=2, axis2=3) - 1) / 2, -1, 1)))
    cen = np.linalg.norm(s * centre(est) @ R.T + t_ - centre(truth), axis=1)
    # mean reprojection error
    U_, _, Vt_ = np.linalg.svd((est[:, :3, :3].transpose(0, 2, 1) @ truth[:, :3, :3]).sum(0))
    Rt = U_ @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U_ @ Vt_))]) @ Vt_
    rel_o = truth[:, :3, :3].transpose(0, 2, 1) @ est[:, :3, :3] @ Rt
    ango = np.degrees(np.arccos(np.clip((np.trace(rel_o, axis1=1, axis2=2) - 1) / 2, -1, 1)))
    ra = subprocess.run(["colmap", "model_analyzer", "--path", str(folder)], capture_output=True, text=True)
    rpe = [l.split(":")[-1] for l in (ra.stdout + ra.stderr).splitlines() if "eproj" in l]
    nobs = [int((im.point3D_ids >= 0).sum()) for im in model.images.values()]
    names = [im.name for im in model.images.values()]
    order = np.argsort(-ango)[:5]
    print("   worst:", [(names[i], round(float(ango[i]),2), round(float(ang[i]),2), nobs[i]) for i in order], "min obs", min(nobs), "median obs", int(np.median(nobs)))
    print(f"{a.tag} rep{rep}: reg {len(est)}/{a.views} pts {len(model.points3D)} rot med {np.median(ang):.3f} max {ang.max():.3f} | pair med {np.median(angp):.3f} max {angp.max():.3f} | cen med {np.median(cen):.3f} | ori med {np.median(ango):.3f} max {ango.max():.3f} | rpe {rpe} | colmap {tc:.1f}s", flush=True)
