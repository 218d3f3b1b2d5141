"""COLMAP's files: the sparse model (binary and text) and the dense depth maps, read and written.

Plain IO, no learning and no renderer: what a reconstruction made by COLMAP (or MegaDepth, which
is made by COLMAP) holds, as numpy arrays, and the conversion of its cameras into this library's
conventions (:mod:`physrelight.camera`).

The sparse model (COLMAP's ``doc/format.rst`` and ``scripts/python/read_write_model.py``):
``cameras``, ``images`` and ``points3D``, each as ``.bin`` (little-endian) or ``.txt``.

* camera: ``CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]``; ``PINHOLE`` has ``fx fy cx cy``,
  ``SIMPLE_PINHOLE`` ``f cx cy``. Only these two are pinhole: every other model carries lens
  distortion, which this library does not model (:func:`pinhole_K` refuses them and says to run
  ``colmap image_undistorter``).
* image: ``IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME`` and its 2-D points ``X Y POINT3D_ID``.
  ``q, t`` are world-to-camera, ``x_cam = R(q) x_world + t``, in COLMAP's camera frame: OpenCV's
  (x right, y down, z forward).
* point: ``POINT3D_ID X Y Z R G B ERROR`` and its track ``(IMAGE_ID, POINT2D_IDX)``.

Frames: this library's camera frame is OpenGL's (x right, y up, z toward the viewer), i.e.
``diag(1, -1, -1)`` of OpenCV's, so ``world_to_camera = F @ [R | t]`` with ``F = diag(1, -1, -1, 1)``
(:func:`world_to_camera_from_colmap`; its inverse :func:`colmap_from_world_to_camera`). Intrinsics
need no change: ``K`` already acts on the OpenCV-style frame here (:mod:`physrelight.camera`), and
COLMAP's pixel convention is this library's (the image's top-left corner at (0, 0), the first
pixel's centre at (0.5, 0.5)).

Dense maps (``stereo/depth_maps/NAME.geometric.bin`` or ``.photometric.bin``, COLMAP's
``src/mvs/mat.h`` and ``scripts/python/read_write_dense.py``): an ASCII header
``WIDTH&HEIGHT&CHANNELS&`` then ``WIDTH*HEIGHT*CHANNELS`` little-endian float32, channel by channel,
each channel row by row (column index fastest). A depth map holds z-depth, 0 where there is none.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO, Callable

import numpy as np

from physrelight.io import atomic_path

__all__ = ["CAMERA_MODELS", "PINHOLE_MODELS", "Camera", "Image", "Point3D", "SparseModel",
           "colmap_from_world_to_camera", "find_sparse_model", "pinhole_K", "qvec_to_rotmat", "read_dense_array",
           "read_model", "rotmat_to_qvec", "world_to_camera_from_colmap", "write_dense_array", "write_model"]

# model id -> (name, number of parameters), COLMAP's src/colmap/sensor/models.h
CAMERA_MODELS: dict[int, tuple[str, int]] = {
    0: ("SIMPLE_PINHOLE", 3), 1: ("PINHOLE", 4), 2: ("SIMPLE_RADIAL", 4), 3: ("RADIAL", 5), 4: ("OPENCV", 8),
    5: ("OPENCV_FISHEYE", 8), 6: ("FULL_OPENCV", 12), 7: ("FOV", 5), 8: ("SIMPLE_RADIAL_FISHEYE", 4),
    9: ("RADIAL_FISHEYE", 5), 10: ("THIN_PRISM_FISHEYE", 12),
}
_MODEL_IDS = {name: (i, n) for i, (name, n) in CAMERA_MODELS.items()}
PINHOLE_MODELS = ("SIMPLE_PINHOLE", "PINHOLE")
_OPENCV_TO_GL = np.diag([1.0, -1.0, -1.0, 1.0])


@dataclass
class Camera:
    """One COLMAP camera: ``model`` (a name of :data:`CAMERA_MODELS`), image size and ``params (P,)`` float64."""

    id: int
    model: str
    width: int
    height: int
    params: np.ndarray


@dataclass
class Image:
    """One registered image: world-to-camera ``qvec (4,)`` (w, x, y, z) and ``tvec (3,)`` in COLMAP's
    (OpenCV) camera frame, its camera, file name, and 2-D points ``xys (N, 2)`` with ``point3D_ids (N,)``
    (-1: not triangulated)."""

    id: int
    qvec: np.ndarray
    tvec: np.ndarray
    camera_id: int
    name: str
    xys: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    point3D_ids: np.ndarray = field(default_factory=lambda: np.zeros((0,), dtype=np.int64))


@dataclass
class Point3D:
    """One 3-D point: ``xyz (3,)``, ``rgb (3,)`` uint8, reprojection ``error``, track ``image_ids (T,)``,
    ``point2D_idxs (T,)``."""

    id: int
    xyz: np.ndarray
    rgb: np.ndarray
    error: float
    image_ids: np.ndarray
    point2D_idxs: np.ndarray


@dataclass
class SparseModel:
    """A sparse model: dicts keyed by id."""

    cameras: dict[int, Camera]
    images: dict[int, Image]
    points3D: dict[int, Point3D]


# ----------------------------------------------------------------------------- frames


def qvec_to_rotmat(qvec: np.ndarray) -> np.ndarray:
    """Rotation ``(3, 3)`` of a quaternion ``(4,)`` ``(w, x, y, z)`` (normalised first; Hamilton, as COLMAP)."""
    q = np.asarray(qvec, dtype=np.float64)
    if q.shape != (4,) or not np.all(np.isfinite(q)) or np.linalg.norm(q) == 0:
        raise ValueError(f"qvec must be 4 finite numbers, not all 0, got {q}")
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def rotmat_to_qvec(R: np.ndarray) -> np.ndarray:
    """Unit quaternion ``(4,)`` ``(w, x, y, z)``, ``w >= 0``, of a rotation ``(3, 3)`` (Shepperd's method:
    the largest of the four squared components first, so no component is found by a near-0 division)."""
    R = np.asarray(R, dtype=np.float64)
    if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
        raise ValueError(f"R must be a (3, 3) proper rotation, got {R}")
    tr = np.trace(R)
    cands = [1 + tr, 1 + 2 * R[0, 0] - tr, 1 + 2 * R[1, 1] - tr, 1 + 2 * R[2, 2] - tr]
    k = int(np.argmax(cands))
    s = 2.0 * np.sqrt(cands[k])
    if k == 0:
        q = [s / 4, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s]
    elif k == 1:
        q = [(R[2, 1] - R[1, 2]) / s, s / 4, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s]
    elif k == 2:
        q = [(R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, s / 4, (R[1, 2] + R[2, 1]) / s]
    else:
        q = [(R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, s / 4]
    q = np.asarray(q)
    return q if q[0] >= 0 else -q


def world_to_camera_from_colmap(qvec: np.ndarray, tvec: np.ndarray) -> np.ndarray:
    """This library's ``world_to_camera (4, 4)`` (OpenGL camera frame) from COLMAP's ``qvec (4,)``,
    ``tvec (3,)`` (OpenCV camera frame): ``diag(1, -1, -1, 1) @ [R | t]``."""
    t = np.asarray(tvec, dtype=np.float64)
    if t.shape != (3,) or not np.all(np.isfinite(t)):
        raise ValueError(f"tvec must be 3 finite numbers, got {t}")
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = qvec_to_rotmat(qvec), t
    return _OPENCV_TO_GL @ T


def colmap_from_world_to_camera(world_to_camera: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """COLMAP's ``(qvec (4,), tvec (3,))`` of this library's ``world_to_camera (4, 4)``; inverse of
    :func:`world_to_camera_from_colmap`."""
    T = np.asarray(world_to_camera, dtype=np.float64)
    if T.shape != (4, 4):
        raise ValueError(f"world_to_camera must be (4, 4), got {T.shape}")
    cv = _OPENCV_TO_GL @ T  # F is its own inverse
    return rotmat_to_qvec(cv[:3, :3]), cv[:3, 3].copy()


def pinhole_K(camera: Camera, where: str = "") -> np.ndarray:
    """``K (3, 3)`` of a ``PINHOLE`` or ``SIMPLE_PINHOLE`` camera; ``ValueError`` for any other model
    (lens distortion: undistort the reconstruction with ``colmap image_undistorter`` first)."""
    p = np.asarray(camera.params, dtype=np.float64)
    if camera.model == "PINHOLE":
        fx, fy, cx, cy = p
    elif camera.model == "SIMPLE_PINHOLE":
        fx, cx, cy = p
        fy = fx
    else:
        raise ValueError(f"{where or 'camera'}: camera {camera.id} is {camera.model}, not a pinhole model "
                         f"({'/'.join(PINHOLE_MODELS)}); run `colmap image_undistorter` and read its output")
    if not (np.isfinite([fx, fy, cx, cy]).all() and fx > 0 and fy > 0):
        raise ValueError(f"{where or 'camera'}: camera {camera.id} has invalid intrinsics {p.tolist()}")
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


# ----------------------------------------------------------------------------- atomic writes


def _atomic(path: Path, write: Callable[[BinaryIO], None]) -> None:
    """Write ``path`` through a temporary file beside it, renamed on success (nothing half-written)."""
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        write(f)


# ----------------------------------------------------------------------------- binary model


class _Reader:
    def __init__(self, path: Path) -> None:
        self.path, self.data, self.pos = path, path.read_bytes(), 0

    def _need(self, size: int) -> int:
        """The offset of the next ``size`` bytes, which are then consumed."""
        if self.pos + size > len(self.data):
            raise ValueError(f"{self.path}: truncated (needs {size} more bytes at offset {self.pos})")
        self.pos += size
        return self.pos - size

    def take(self, fmt: str) -> tuple:
        return struct.unpack_from("<" + fmt, self.data, self._need(struct.calcsize("<" + fmt)))

    def array(self, dtype: np.dtype, count: int) -> np.ndarray:
        at = self._need(np.dtype(dtype).itemsize * count)
        return np.frombuffer(self.data, dtype=dtype, count=count, offset=at).copy()

    def cstring(self) -> str:
        end = self.data.find(b"\x00", self.pos)
        if end < 0:
            raise ValueError(f"{self.path}: truncated (an image name without its terminating 0)")
        out = self.data[self.pos:end].decode("utf-8")
        self.pos = end + 1
        return out

    def records(self, read_one: Callable[[], tuple[int, Any]]) -> dict[int, Any]:
        """A binary model file: a uint64 count, then that many records by ``read_one`` (each ``(id, record)``),
        and nothing after them."""
        out = dict(read_one() for _ in range(self.take("Q")[0]))
        if self.pos != len(self.data):
            raise ValueError(f"{self.path}: {len(self.data) - self.pos} bytes after the last record")
        return out


_POINT2D = np.dtype([("x", "<f8"), ("y", "<f8"), ("id", "<i8")])
_TRACK = np.dtype([("image", "<i4"), ("idx", "<i4")])


def _read_cameras_bin(path: Path) -> dict[int, Camera]:
    r = _Reader(path)

    def one() -> tuple[int, Camera]:
        cid, mid, w, h = r.take("iiQQ")
        if mid not in CAMERA_MODELS:
            raise ValueError(f"{path}: camera {cid} has unknown model id {mid}")
        name, n = CAMERA_MODELS[mid]
        return cid, Camera(cid, name, int(w), int(h), np.array(r.take("d" * n)))

    return r.records(one)


def _read_images_bin(path: Path) -> dict[int, Image]:
    r = _Reader(path)

    def one() -> tuple[int, Image]:
        props = r.take("idddddddi")
        name = r.cstring()
        pts = r.array(_POINT2D, r.take("Q")[0])
        return props[0], Image(props[0], np.array(props[1:5]), np.array(props[5:8]), props[8], name,
                               np.stack([pts["x"], pts["y"]], 1), pts["id"].astype(np.int64))

    return r.records(one)


def _read_points3D_bin(path: Path) -> dict[int, Point3D]:
    r = _Reader(path)

    def one() -> tuple[int, Point3D]:
        props = r.take("QdddBBBd")
        track = r.array(_TRACK, r.take("Q")[0])
        return props[0], Point3D(props[0], np.array(props[1:4]), np.array(props[4:7], dtype=np.uint8), props[7],
                                 track["image"].astype(np.int64), track["idx"].astype(np.int64))

    return r.records(one)


def _write_cameras_bin(cameras: dict[int, Camera], f: BinaryIO) -> None:
    f.write(struct.pack("<Q", len(cameras)))
    for c in cameras.values():
        mid, n = _model_id(c)
        f.write(struct.pack("<iiQQ", c.id, mid, c.width, c.height))
        f.write(struct.pack("<" + "d" * n, *np.asarray(c.params, dtype=np.float64)))


def _write_images_bin(images: dict[int, Image], f: BinaryIO) -> None:
    f.write(struct.pack("<Q", len(images)))
    for im in images.values():
        f.write(struct.pack("<idddddddi", im.id, *np.asarray(im.qvec, float), *np.asarray(im.tvec, float),
                            im.camera_id))
        f.write(im.name.encode("utf-8") + b"\x00")
        pts = np.zeros(len(im.point3D_ids), dtype=_POINT2D)
        if len(pts):
            pts["x"], pts["y"], pts["id"] = im.xys[:, 0], im.xys[:, 1], im.point3D_ids
        f.write(struct.pack("<Q", len(pts)) + pts.tobytes())


def _write_points3D_bin(points: dict[int, Point3D], f: BinaryIO) -> None:
    f.write(struct.pack("<Q", len(points)))
    for p in points.values():
        f.write(struct.pack("<QdddBBBd", p.id, *np.asarray(p.xyz, float), *np.asarray(p.rgb, np.uint8).tolist(),
                            p.error))
        track = np.zeros(len(p.image_ids), dtype=_TRACK)
        track["image"], track["idx"] = p.image_ids, p.point2D_idxs
        f.write(struct.pack("<Q", len(track)) + track.tobytes())


def _model_id(c: Camera) -> tuple[int, int]:
    if c.model not in _MODEL_IDS:
        raise ValueError(f"camera {c.id}: unknown model {c.model!r}; known: {sorted(_MODEL_IDS)}")
    mid, n = _MODEL_IDS[c.model]
    if len(c.params) != n:
        raise ValueError(f"camera {c.id}: {c.model} has {n} parameters, got {len(c.params)}")
    return mid, n


# ----------------------------------------------------------------------------- text model


def _data_lines(path: Path) -> list[str]:
    """Lines of a text model without comments; image files keep their (possibly empty) points lines."""
    return [ln.rstrip("\r\n") for ln in path.read_text().splitlines() if not ln.startswith("#")]


def _read_cameras_txt(path: Path) -> dict[int, Camera]:
    out = {}
    for ln in _data_lines(path):
        if not ln.strip():
            continue
        el = ln.split()
        try:
            cid, model, w, h = int(el[0]), el[1], int(el[2]), int(el[3])
            params = np.array([float(x) for x in el[4:]])
        except (IndexError, ValueError):
            raise ValueError(f"{path}: not a camera line: {ln!r}") from None
        if model in _MODEL_IDS and len(params) != _MODEL_IDS[model][1]:
            raise ValueError(f"{path}: camera {cid} ({model}) has {len(params)} parameters, expected "
                             f"{_MODEL_IDS[model][1]}")
        out[cid] = Camera(cid, model, w, h, params)
    return out


def _read_images_txt(path: Path) -> dict[int, Image]:
    lines = _data_lines(path)
    while lines and not lines[-1].strip():  # a trailing newline; an image's empty points line is not at the end
        lines.pop()
    out = {}
    i = 0
    while i < len(lines):
        head = lines[i]
        if not head.strip():
            i += 1
            continue
        el = head.split(maxsplit=9)
        pts_line = lines[i + 1] if i + 1 < len(lines) else ""
        i += 2
        try:
            iid, cid, name = int(el[0]), int(el[8]), el[9]
            q, t = [float(x) for x in el[1:5]], [float(x) for x in el[5:8]]
            pts = pts_line.split()
            if len(pts) % 3:
                raise ValueError
            xys = np.array([[float(pts[k]), float(pts[k + 1])] for k in range(0, len(pts), 3)]).reshape(-1, 2)
            ids = np.array([int(pts[k + 2]) for k in range(0, len(pts), 3)], dtype=np.int64)
        except (IndexError, ValueError):
            raise ValueError(f"{path}: not an image record: {head!r}") from None
        out[iid] = Image(iid, np.array(q), np.array(t), cid, name, xys, ids)
    return out


def _read_points3D_txt(path: Path) -> dict[int, Point3D]:
    out = {}
    for ln in _data_lines(path):
        if not ln.strip():
            continue
        el = ln.split()
        try:
            pid = int(el[0])
            track = np.array([int(x) for x in el[8:]], dtype=np.int64)
            if len(track) % 2:
                raise ValueError
            out[pid] = Point3D(pid, np.array([float(x) for x in el[1:4]]), np.array([int(x) for x in el[4:7]],
                                                                                     dtype=np.uint8),
                               float(el[7]), track[0::2], track[1::2])
        except (IndexError, ValueError):
            raise ValueError(f"{path}: not a point line: {ln!r}") from None
    return out


def _write_cameras_txt(cameras: dict[int, Camera], f: BinaryIO) -> None:
    lines = ["# Camera list with one line of data per camera:",
             "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]", f"# Number of cameras: {len(cameras)}"]
    for c in cameras.values():
        _model_id(c)
        lines.append(" ".join([str(c.id), c.model, str(c.width), str(c.height), *map(repr, map(float, c.params))]))
    f.write(("\n".join(lines) + "\n").encode())


def _write_images_txt(images: dict[int, Image], f: BinaryIO) -> None:
    lines = ["# Image list with two lines of data per image:",
             "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME",
             "#   POINTS2D[] as (X, Y, POINT3D_ID)", f"# Number of images: {len(images)}"]
    for im in images.values():
        lines.append(" ".join([str(im.id), *map(repr, map(float, im.qvec)), *map(repr, map(float, im.tvec)),
                               str(im.camera_id), im.name]))
        lines.append(" ".join(f"{float(x)!r} {float(y)!r} {int(p)}" for (x, y), p in zip(im.xys, im.point3D_ids)))
    f.write(("\n".join(lines) + "\n").encode())


def _write_points3D_txt(points: dict[int, Point3D], f: BinaryIO) -> None:
    lines = ["# 3D point list with one line of data per point:",
             "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)",
             f"# Number of points: {len(points)}"]
    for p in points.values():
        track = " ".join(f"{int(a)} {int(b)}" for a, b in zip(p.image_ids, p.point2D_idxs))
        lines.append(" ".join([str(p.id), *map(repr, map(float, p.xyz)), *map(str, map(int, p.rgb)),
                               repr(float(p.error)), track]).rstrip())
    f.write(("\n".join(lines) + "\n").encode())


_READERS = {".bin": (_read_cameras_bin, _read_images_bin, _read_points3D_bin),
            ".txt": (_read_cameras_txt, _read_images_txt, _read_points3D_txt)}
_WRITERS = {".bin": (_write_cameras_bin, _write_images_bin, _write_points3D_bin),
            ".txt": (_write_cameras_txt, _write_images_txt, _write_points3D_txt)}
_FILES = ("cameras", "images", "points3D")


def _model_ext(folder: Path) -> str | None:
    """``".bin"`` or ``".txt"`` when ``folder`` holds a complete model in that form (binary first, as COLMAP)."""
    for ext in (".bin", ".txt"):
        if all((folder / f"{n}{ext}").is_file() for n in _FILES):
            return ext
    return None


def find_sparse_model(folder: str | Path) -> Path | None:
    """The folder holding a sparse model: ``folder`` itself, else ``folder/0`` (``mapper``'s first
    model), else None."""
    folder = Path(folder)
    for cand in (folder, folder / "0"):
        if cand.is_dir() and _model_ext(cand):
            return cand
    return None


def read_model(folder: str | Path) -> SparseModel:
    """Read the sparse model in ``folder`` (``cameras``, ``images``, ``points3D``; ``.bin`` when all three
    are there, else ``.txt``); ``ValueError`` naming the file when one is malformed or an image names a
    camera the model lacks."""
    folder = Path(folder)
    ext = _model_ext(folder)
    if ext is None:
        raise FileNotFoundError(f"{folder}: no COLMAP sparse model (cameras, images, points3D as .bin or .txt)")
    cams, ims, pts = (reader(folder / f"{n}{ext}") for reader, n in zip(_READERS[ext], _FILES))
    for im in ims.values():
        if im.camera_id not in cams:
            raise ValueError(f"{folder / f'images{ext}'}: image {im.name!r} names camera {im.camera_id}, "
                             f"which {folder / f'cameras{ext}'} lacks")
    return SparseModel(cams, ims, pts)


def write_model(model: SparseModel, folder: str | Path, ext: str = ".bin") -> None:
    """Write ``model`` into ``folder`` (made if missing) as ``.bin`` or ``.txt``; each file atomically."""
    if ext not in _WRITERS:
        raise ValueError(f"ext must be '.bin' or '.txt', got {ext!r}")
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    for writer, n, data in zip(_WRITERS[ext], _FILES, (model.cameras, model.images, model.points3D)):
        _atomic(folder / f"{n}{ext}", lambda f, w=writer, d=data: w(d, f))


# ----------------------------------------------------------------------------- dense maps

_HEADER = re.compile(rb"^(\d+)&(\d+)&(\d+)&")


def read_dense_array(path: str | Path) -> np.ndarray:
    """A COLMAP dense map: ``(H, W)`` float32 for one channel, else ``(H, W, C)``; ``ValueError`` naming
    the file when its header or its size is wrong."""
    path = Path(path)
    data = path.read_bytes()
    m = _HEADER.match(data[:64])
    if m is None:
        raise ValueError(f"{path}: not a COLMAP dense map (no 'width&height&channels&' header)")
    w, h, c = (int(g) for g in m.groups())
    body = data[m.end():]
    if len(body) != 4 * w * h * c or w * h * c == 0:
        raise ValueError(f"{path}: header says {w}x{h}x{c} float32 ({4 * w * h * c} bytes), the file holds "
                         f"{len(body)}")
    planes = np.frombuffer(body, dtype="<f4").reshape(c, h, w)  # channel-major, each row-major
    out = np.ascontiguousarray(planes.transpose(1, 2, 0)).astype(np.float32)
    return out[..., 0] if c == 1 else out


def write_dense_array(array: np.ndarray, path: str | Path) -> None:
    """Write ``(H, W)`` or ``(H, W, C)`` float32 as a COLMAP dense map (atomically)."""
    a = np.asarray(array)
    if a.dtype != np.float32 or a.ndim not in (2, 3):
        raise ValueError(f"a dense map is float32 (H, W) or (H, W, C), got {a.dtype} {a.shape}")
    a = a[..., None] if a.ndim == 2 else a
    h, w, c = a.shape
    body = np.ascontiguousarray(a.transpose(2, 0, 1)).astype("<f4").tobytes()
    _atomic(Path(path), lambda f: f.write(f"{w}&{h}&{c}&".encode() + body))
