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
for rep in range(a.reps):
    work = root / f"sfm_{a.tag}_{rep}"
    shutil.rmtree(work, ignore_errors=True)
    t = time.time()
    T.reconstruct(root, work, K, a.maxerr, tuple(a.extra.split()))
    folder = cf.find_sparse_model(work / "sparse")
    if a.ba:
        (work / "ba").mkdir()
        T._colmap("bundle_adjuster", "--input_path", str(folder), "--output_path", str(work / "ba"),
            "--BundleAdjustment.max_num_iterations", "500", "--BundleAdjustment.refine_focal_length", "0",
            "--BundleAdjustment.refine_principal_point", "0", "--BundleAdjustment.refine_extra_params", "0",
            "--BundleAdjustment.function_tolerance", "1e-10", "--BundleAdjustment.gradient_tolerance", "1e-12", "--BundleAdjustment.parameter_tolerance", "1e-10", cwd=work)
        folder = work / "ba"
    tc = time.time() - t
    model = cf.read_model(folder)
    truth = np.stack([poses[int(im.name[1:3])] for im in model.images.values()])
    est = np.stack([cf.world_to_camera_from_colmap(im.qvec, im.tvec) for im in model.images.values()])
    e = T.pose_errors(truth, est)
    ang, ango, angp, cen = e["angles"], e["oriented"], e["pairwise"], e["centres"]
    ra = subprocess.run(["colmap", "model_analyzer", "--path", str(folder)], capture_output=True, text=True)
    rpe = [l.split(":")[-1] for l in (ra.stdout + ra.stderr).splitlines() if "eproj" in l]
    nobs = [int((im.point3D_ids >= 0).sum()) for im in model.images.values()]
    names = [im.name for im in model.images.values()]
    order = np.argsort(-ango)[:5]
    print("   worst:", [(names[i], round(float(ango[i]),2), round(float(ang[i]),2), nobs[i]) for i in order], "min obs", min(nobs), "median obs", int(np.median(nobs)))
    print(f"{a.tag} rep{rep}: reg {len(est)}/{a.views} pts {len(model.points3D)} rot med {np.median(ang):.3f} max {ang.max():.3f} | pair med {np.median(angp):.3f} max {angp.max():.3f} | cen med {np.median(cen):.3f} | ori med {np.median(ango):.3f} max {ango.max():.3f} | rpe {rpe} | colmap {tc:.1f}s", flush=True)
