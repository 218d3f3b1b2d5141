"""COLMAP's sparse model and dense maps (physrelight.colmap_format): the documented layouts, frames, refusals."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest
import torch

from physrelight import camera
from physrelight import colmap_format as cf


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q * np.sign(np.linalg.det(q))


def _model(rng: np.random.Generator) -> cf.SparseModel:
    cams = {1: cf.Camera(1, "PINHOLE", 64, 48, np.array([70.5, 71.25, 32.0, 24.5])),
            3: cf.Camera(3, "SIMPLE_PINHOLE", 40, 40, np.array([50.0, 20.0, 20.0])),
            7: cf.Camera(7, "OPENCV", 40, 30, rng.normal(size=8))}
    ims = {}
    for iid, cid, name in ((2, 1, "a.jpg"), (5, 3, "sub dir/b c.png"), (9, 7, "c.JPG")):
        n = int(rng.integers(0, 4))
        ims[iid] = cf.Image(iid, cf.rotmat_to_qvec(_random_rotation(rng)), rng.normal(size=3), cid, name,
                            rng.uniform(0, 40, size=(n, 2)), rng.integers(-1, 5, size=n))
    pts = {4: cf.Point3D(4, rng.normal(size=3), np.array([1, 2, 250], np.uint8), 0.75, np.array([2, 5]),
                         np.array([0, 1])),
           11: cf.Point3D(11, rng.normal(size=3), np.array([0, 0, 0], np.uint8), 1.5, np.array([9]), np.array([2]))}
    return cf.SparseModel(cams, ims, pts)


def _same(a: cf.SparseModel, b: cf.SparseModel, exact: bool) -> None:
    close = (lambda x, y: np.array_equal(x, y)) if exact else (lambda x, y: np.allclose(x, y, rtol=0, atol=1e-12))
    assert a.cameras.keys() == b.cameras.keys() and a.images.keys() == b.images.keys()
    assert a.points3D.keys() == b.points3D.keys()
    for k, c in a.cameras.items():
        d = b.cameras[k]
        assert (c.model, c.width, c.height) == (d.model, d.width, d.height) and close(c.params, d.params)
    for k, i in a.images.items():
        j = b.images[k]
        assert (i.name, i.camera_id) == (j.name, j.camera_id)
        assert close(i.qvec, j.qvec) and close(i.tvec, j.tvec) and close(i.xys.reshape(-1, 2), j.xys)
        assert np.array_equal(i.point3D_ids, j.point3D_ids)
    for k, p in a.points3D.items():
        q = b.points3D[k]
        assert close(p.xyz, q.xyz) and np.array_equal(p.rgb, q.rgb) and p.error == q.error
        assert np.array_equal(p.image_ids, q.image_ids) and np.array_equal(p.point2D_idxs, q.point2D_idxs)


@pytest.mark.parametrize("ext", [".bin", ".txt"])
def test_01_sparse_model_round_trips(tmp_path: Path, ext: str) -> None:
    model = _model(np.random.default_rng(1))
    cf.write_model(model, tmp_path, ext)
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"cameras{ext}", f"images{ext}", f"points3D{ext}"]
    _same(model, cf.read_model(tmp_path), exact=True)  # text writes repr(float): exact too


def test_02_binary_layout_is_colmaps(tmp_path: Path) -> None:
    """Bytes packed by hand from the documented record layout read back as the model."""
    q, t = [0.5, 0.5, -0.5, 0.5], [1.0, 2.0, 3.0]
    (tmp_path / "cameras.bin").write_bytes(struct.pack("<Q", 1) + struct.pack("<iiQQ", 7, 1, 64, 48)
                                           + struct.pack("<4d", 60.0, 61.0, 32.0, 24.0))
    (tmp_path / "images.bin").write_bytes(struct.pack("<Q", 1) + struct.pack("<i4d3di", 3, *q, *t, 7) + b"x.png\x00"
                                          + struct.pack("<Q", 2) + struct.pack("<ddq", 1.5, 2.5, -1)
                                          + struct.pack("<ddq", 3.5, 4.5, 12))
    (tmp_path / "points3D.bin").write_bytes(struct.pack("<Q", 1) + struct.pack("<Q3d3Bd", 12, 0.1, 0.2, 0.3,
                                                                                  9, 8, 7, 0.25)
                                            + struct.pack("<Q", 1) + struct.pack("<ii", 3, 1))
    m = cf.read_model(tmp_path)
    assert m.cameras[7].model == "PINHOLE" and m.cameras[7].params.tolist() == [60.0, 61.0, 32.0, 24.0]
    im = m.images[3]
    assert im.name == "x.png" and im.qvec.tolist() == q and im.tvec.tolist() == t
    assert im.xys.tolist() == [[1.5, 2.5], [3.5, 4.5]] and im.point3D_ids.tolist() == [-1, 12]
    assert m.points3D[12].rgb.tolist() == [9, 8, 7] and m.points3D[12].image_ids.tolist() == [3]
    # and the writer produces exactly those bytes
    out = tmp_path / "out"
    cf.write_model(m, out, ".bin")
    for n in ("cameras", "images", "points3D"):
        assert (out / f"{n}.bin").read_bytes() == (tmp_path / f"{n}.bin").read_bytes()


def test_03_text_layout_is_the_documented_example(tmp_path: Path) -> None:
    """COLMAP's doc/format.rst example lines (comments, an image without points: an empty line)."""
    (tmp_path / "cameras.txt").write_text(
        "# Camera list with one line of data per camera:\n#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
        "# Number of cameras: 3\n1 SIMPLE_PINHOLE 3072 2304 2559.81 1536 1152\n"
        "2 PINHOLE 3072 2304 2560.56 2560.56 1536 1152\n3 SIMPLE_RADIAL 3072 2304 2559.69 1536 1152 -0.0218531\n")
    (tmp_path / "images.txt").write_text(
        "# Image list with two lines of data per image:\n"
        "1 0.851773 0.0165051 0.503764 -0.142941 -0.737434 1.02973 3.74354 1 P1180141.JPG\n"
        "2362.39 248.498 58396 1784.7 268.254 59027\n"
        "2 0.851773 0.0165051 0.503764 -0.142941 -0.737434 1.02973 3.74354 2 P1180142.JPG\n\n")
    (tmp_path / "points3D.txt").write_text(
        "# 3D point list with one line of data per point:\n"
        "63390 1.67241 0.292931 0.609726 115 121 122 1.33927 16 6542 15 7345 6 6714 14 7227\n")
    m = cf.read_model(tmp_path)
    assert m.cameras[3].model == "SIMPLE_RADIAL" and m.cameras[1].params.tolist() == [2559.81, 1536, 1152]
    assert m.images[1].point3D_ids.tolist() == [58396, 59027] and len(m.images[2].xys) == 0
    assert m.points3D[63390].image_ids.tolist() == [16, 15, 6, 14]
    assert m.points3D[63390].point2D_idxs.tolist() == [6542, 7345, 6714, 7227]
    np.testing.assert_allclose(cf.pinhole_K(m.cameras[1]), [[2559.81, 0, 1536], [0, 2559.81, 1152], [0, 0, 1]])
    with pytest.raises(ValueError, match="SIMPLE_RADIAL.*image_undistorter"):
        cf.pinhole_K(m.cameras[3])


def test_04_dense_map_layout_is_colmaps(tmp_path: Path) -> None:
    """Header ``W&H&C&`` then float32, channel by channel, each row by row (mat.h): checked on bytes."""
    a = np.arange(6, dtype=np.float32).reshape(2, 3) + 0.5  # 2 rows, 3 columns
    p = tmp_path / "x.geometric.bin"
    cf.write_dense_array(a, p)
    assert p.read_bytes() == b"3&2&1&" + struct.pack("<6f", 0.5, 1.5, 2.5, 3.5, 4.5, 5.5)
    np.testing.assert_array_equal(cf.read_dense_array(p), a)
    rgb = np.random.default_rng(0).normal(size=(4, 5, 3)).astype(np.float32)
    cf.write_dense_array(rgb, p)
    body = p.read_bytes()[len(b"5&4&3&"):]
    np.testing.assert_array_equal(np.frombuffer(body, "<f4").reshape(3, 4, 5), rgb.transpose(2, 0, 1))
    np.testing.assert_array_equal(cf.read_dense_array(p), rgb)


def test_05_quaternions_match_scipy_and_round_trip() -> None:
    Rotation = pytest.importorskip("scipy.spatial.transform").Rotation
    rng = np.random.default_rng(2)
    mats = [_random_rotation(rng) for _ in range(200)] + [np.diag([1.0, -1, -1]), np.diag([-1.0, 1, -1]), np.eye(3)]
    for R in mats:
        q = cf.rotmat_to_qvec(R)
        x, y, z, w = Rotation.from_matrix(R).as_quat()
        assert np.allclose(q, np.sign(w or 1) * np.array([w, x, y, z]), atol=1e-12) or np.allclose(
            q, -np.array([w, x, y, z]), atol=1e-12)
        np.testing.assert_allclose(cf.qvec_to_rotmat(q), R, atol=1e-12)


def test_06_a_point_projects_to_the_same_pixel_in_both_conventions() -> None:
    """COLMAP: x = R X + t (OpenCV frame), u = fx x/z + cx, pixel centres at +0.5 like here. The converted
    world_to_camera with this library's projection gives the same pixel."""
    rng = np.random.default_rng(3)
    K = np.array([[80.0, 0, 33.5], [0, 82.0, 23.25], [0, 0, 1]])
    for _ in range(20):
        R, t = _random_rotation(rng), rng.normal(size=3)
        q = cf.rotmat_to_qvec(R)
        X = rng.normal(size=(50, 3)) * 0.5
        x = X @ cf.qvec_to_rotmat(q).T + t
        x = x[x[:, 2] > 0.1]
        uv_colmap = np.stack([K[0, 0] * x[:, 0] / x[:, 2] + K[0, 2], K[1, 1] * x[:, 1] / x[:, 2] + K[1, 2]], 1)
        T = cf.world_to_camera_from_colmap(q, t)
        p = camera.transform_points(torch.from_numpy(T), torch.from_numpy(X))  # (N, 3)
        uv, depth = camera.project(p.T[None], torch.from_numpy(K))
        keep = (X @ cf.qvec_to_rotmat(q).T + t)[:, 2] > 0.1
        np.testing.assert_allclose(uv[0].numpy().T[keep], uv_colmap, atol=1e-9)
        np.testing.assert_allclose(depth[0, 0].numpy()[keep], x[:, 2], atol=1e-12)  # COLMAP's z is the depth
        q2, t2 = cf.colmap_from_world_to_camera(T)
        np.testing.assert_allclose(cf.qvec_to_rotmat(q2), cf.qvec_to_rotmat(q), atol=1e-12)
        np.testing.assert_allclose(t2, t, atol=1e-15)


def test_07_bad_files_are_refused_naming_them(tmp_path: Path) -> None:
    cf.write_model(_model(np.random.default_rng(4)), tmp_path, ".bin")
    data = (tmp_path / "images.bin").read_bytes()
    (tmp_path / "images.bin").write_bytes(data[:-5])
    with pytest.raises(ValueError, match="images.bin: truncated"):
        cf.read_model(tmp_path)
    (tmp_path / "images.bin").write_bytes(data + b"\x00")
    with pytest.raises(ValueError, match="images.bin: 1 bytes after"):
        cf.read_model(tmp_path)
    (tmp_path / "images.bin").write_bytes(data)
    cams = cf.read_model(tmp_path).cameras
    del cams[3]
    cf.write_model(cf.SparseModel(cams, cf.read_model(tmp_path).images, {}), tmp_path / "m2", ".txt")
    with pytest.raises(ValueError, match="names camera 3"):
        cf.read_model(tmp_path / "m2")
    with pytest.raises(FileNotFoundError, match="no COLMAP sparse model"):
        cf.read_model(tmp_path / "nothing")
    d = tmp_path / "d.bin"
    d.write_bytes(b"4&4&1&" + b"\x00" * 60)
    with pytest.raises(ValueError, match=r"d.bin: header says 4x4x1"):
        cf.read_dense_array(d)
    d.write_bytes(b"garbage")
    with pytest.raises(ValueError, match="d.bin: not a COLMAP dense map"):
        cf.read_dense_array(d)


def test_08_find_sparse_model_takes_the_folder_or_its_0(tmp_path: Path) -> None:
    assert cf.find_sparse_model(tmp_path) is None
    cf.write_model(_model(np.random.default_rng(5)), tmp_path / "0", ".txt")
    assert cf.find_sparse_model(tmp_path) == tmp_path / "0"
    cf.write_model(_model(np.random.default_rng(5)), tmp_path, ".bin")
    assert cf.find_sparse_model(tmp_path) == tmp_path
