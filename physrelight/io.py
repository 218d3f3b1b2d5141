"""Image and JSON IO at the library's boundary, with atomic writes.

Inside the library images are linear torch ``(B, C, H, W)``; files hold numpy
``(H, W, C)``. PNG/JPEG are display-referred (sRGB-encoded 8 bit); HDR data goes to EXR
through :mod:`physrelight.envmap`. Every write goes to a temporary file in the target
folder and is renamed into place, so a killed process never leaves half a file.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import torch

from physrelight._checks import Array, to_tensor


def _read_umask() -> int:
    # Reading the umask means setting it; done once at import, before any thread writes a
    # file, so no other file is ever created while it is 0.
    mask = os.umask(0)
    os.umask(mask)
    return mask


_UMASK = _read_umask()


def canonical_safetensors(data: bytes) -> bytes:
    """The safetensors file ``data`` with its JSON header's keys sorted.

    safetensors writes the metadata from a hash map, so two writes of the same tensors differed in the
    header's key order (same content, different bytes). Sorting the keys makes a file a function of its
    content; the format is unchanged (an 8-byte little-endian header length, the JSON header padded with
    spaces to a multiple of 8, the data).
    """
    n = int.from_bytes(data[:8], "little")
    header = json.dumps(json.loads(data[8:8 + n]), sort_keys=True, separators=(",", ":")).encode()
    header += b" " * (-(8 + len(header)) % 8)
    return len(header).to_bytes(8, "little") + header + data[8 + n:]


@contextmanager
def atomic_path(path: str | os.PathLike, suffix: str = "") -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` if the block succeeds."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=suffix or p.suffix, dir=p.parent)
    os.close(fd)
    # mkstemp creates 0600; give the file the mode an ordinary open() would (0666 & ~umask).
    os.chmod(tmp, 0o666 & ~_UMASK)
    try:
        yield Path(tmp)
        os.replace(tmp, p)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def write_exr(path: str | os.PathLike, image: Array) -> None:
    """Write a float image as a lossless (ZIP) float32 EXR, atomically.

    ``(H, W, 3)`` is stored as RGB, ``(H, W)`` as a single channel ``Y``.
    """
    import OpenEXR

    t, _ = to_tensor(image, "image")
    arr = np.ascontiguousarray(t.detach().cpu().numpy().astype(np.float32))
    if arr.ndim == 3 and arr.shape[-1] == 3:
        channels = {"RGB": arr}
    elif arr.ndim == 2:
        channels = {"Y": arr}
    else:
        raise ValueError(f"image must have shape (H, W, 3) or (H, W), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError("image holds non-finite values (NaN or inf)")
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with atomic_path(path, ".exr") as tmp:
        with OpenEXR.File(header, channels) as f:
            f.write(str(tmp))


def read_exr(path: str | os.PathLike) -> np.ndarray:
    """Read an EXR as float32: ``(H, W, 3)`` for R, G, B (alpha dropped), ``(H, W)`` for one channel.

    Raises ``ValueError`` naming the file when it is missing, unreadable, or holds other channels.
    """
    import OpenEXR

    p = Path(path)
    if not p.is_file():
        raise ValueError(f"{str(p)!r} does not exist")
    try:
        channels = OpenEXR.File(str(p), separate_channels=True).channels()
    except Exception as err:  # OpenEXR raises bare exceptions with C++ messages
        raise ValueError(f"cannot read {str(p)!r} as EXR: {err}") from None
    names = {k.split(".")[-1].upper(): k for k in channels}
    if {"R", "G", "B"} <= set(names):
        return np.stack([np.asarray(channels[names[c]].pixels, dtype=np.float32) for c in "RGB"], axis=-1)
    if len(channels) == 1:
        return np.asarray(next(iter(channels.values())).pixels, dtype=np.float32)
    raise ValueError(f"{str(p)!r} must have R, G, B channels or a single channel, found {sorted(channels)}")


DWA_NEGATIVE_TOLERANCE = 1e-2
"""Lossy (DWA) EXR compression leaves small negative ringing round bright texels (seen down to -2e-3 next to a
1.4e3 sun in the shared maps); below ``-DWA_NEGATIVE_TOLERANCE * max(1, p99.9)`` an image is refused, not
clamped: a broken map, not compression noise."""


def read_radiance(path: str | os.PathLike) -> np.ndarray:
    """Read an EXR (or Radiance ``.hdr``) RGB image as linear radiance ``float32 (H, W, 3)``: an environment map,
    a render, an HDR photo.

    The alpha channel, if any, is dropped. Slightly negative values from lossy (DWA) compression are clamped to 0;
    a single channel, NaN/inf or strongly negative values raise ``ValueError`` naming the file.
    """
    rgb = read_hdr(path) if str(path).lower().endswith(".hdr") else read_exr(path)
    if rgb.ndim != 3:
        raise ValueError(f"{str(path)!r} must have R, G, B channels, found a single channel")
    if not np.all(np.isfinite(rgb)):
        raise ValueError(f"{str(path)!r} holds non-finite values (NaN or inf)")
    if rgb.size and rgb.min() < -DWA_NEGATIVE_TOLERANCE * max(1.0, float(np.percentile(rgb, 99.9))):
        raise ValueError(f"{str(path)!r} holds strongly negative radiance (min {rgb.min():.4g})")
    return np.clip(rgb, 0.0, None)


def read_hdr(path: str | os.PathLike) -> np.ndarray:
    """Read a Radiance RGBE ``.hdr`` file as float32 ``(H, W, 3)`` linear radiance.

    Supports the standard ``-Y H +X W`` orientation, flat and run-length-encoded
    scanlines (the "new" RLE every current writer uses); ``(m + 0.5) * 2**(e - 136)`` as in
    Radiance's ``colr_color``, 0 where the exponent is 0. Anything else raises a
    ``ValueError`` naming the problem.
    """
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"HDR image {str(p)!r} does not exist")
    data = p.read_bytes()
    if not (data.startswith(b"#?RADIANCE") or data.startswith(b"#?RGBE")):
        raise ValueError(f"{str(p)!r} is not a Radiance .hdr file (no #?RADIANCE header)")
    end = data.find(b"\n\n")
    if end < 0:
        raise ValueError(f"{str(p)!r}: truncated header")
    header = data[:end].decode("ascii", "replace")
    fmt = [ln for ln in header.splitlines() if ln.startswith("FORMAT=")]
    if fmt and fmt[0].strip() != "FORMAT=32-bit_rle_rgbe":
        raise ValueError(f"{str(p)!r}: unsupported {fmt[0].strip()} (only 32-bit_rle_rgbe)")
    nl = data.find(b"\n", end + 2)
    res = data[end + 2:nl].decode("ascii", "replace").split()
    if len(res) != 4 or res[0] != "-Y" or res[2] != "+X" or not (res[1].isdigit() and res[3].isdigit()):
        raise ValueError(f"{str(p)!r}: unsupported resolution line {' '.join(res)!r} (only '-Y H +X W')")
    h, w = int(res[1]), int(res[3])
    buf = np.frombuffer(data, dtype=np.uint8, offset=nl + 1)
    out = np.empty((h, w, 4), dtype=np.uint8)
    pos = 0
    try:
        for y in range(h):
            if 8 <= w < 32768 and buf[pos] == 2 and buf[pos + 1] == 2 and not buf[pos + 2] & 0x80:
                if (int(buf[pos + 2]) << 8 | int(buf[pos + 3])) != w:
                    raise ValueError("scanline width mismatch")
                pos += 4
                for c in range(4):
                    x = 0
                    while x < w:
                        n = int(buf[pos])
                        if n > 128:  # a run
                            n -= 128
                            out[y, x:x + n, c] = buf[pos + 1]
                            pos += 2
                        else:
                            if n == 0 or x + n > w:
                                raise ValueError("bad run length")
                            out[y, x:x + n, c] = buf[pos + 1:pos + 1 + n]
                            pos += 1 + n
                        x += n
                    if x != w:
                        raise ValueError("run overflows the scanline")
            else:
                out[y] = buf[pos:pos + 4 * w].reshape(w, 4)
                pos += 4 * w
    except (IndexError, ValueError) as err:
        raise ValueError(f"{str(p)!r}: corrupt or truncated pixel data ({err})") from None
    e = out[..., 3].astype(np.int32)
    scale = np.where(e > 0, np.ldexp(1.0, e - 136), 0.0)
    return ((out[..., :3].astype(np.float64) + 0.5) * scale[..., None]).astype(np.float32)


def read_image(path: str | os.PathLike) -> np.ndarray:
    """Read a PNG/JPEG photo as float32 ``(H, W, 3)`` display values in [0, 1] (sRGB-encoded).

    Linearise with :func:`physrelight.colour.from_ldr`. Grey-scale, palette and RGBA
    images are rejected with a ``ValueError`` naming the mode, rather than guessed at.
    """
    from PIL import Image, UnidentifiedImageError

    p = Path(path)
    if not p.is_file():
        raise ValueError(f"image {str(p)!r} does not exist")
    try:
        with Image.open(p) as im:
            im.load()
            mode = im.mode
            if mode == "RGBA":
                im = im.convert("RGB")
            elif mode != "RGB":
                raise ValueError(f"{str(p)!r} is a {mode!r} image; an RGB colour photo is needed")
            arr = np.asarray(im)
    except (UnidentifiedImageError, OSError) as err:
        raise ValueError(f"cannot read {str(p)!r} as an image: {err}") from None
    return arr.astype(np.float32) / 255.0


@dataclass
class Photo:
    """A photo as a camera wrote it: display values (or a render's linear radiance), upright, and what its
    metadata says.

    Attributes:
        image: ``(H, W, 3)`` float32 display values in [0, 1] (sRGB-encoded), turned upright by
            its EXIF orientation; linear radiance when ``radiance``.
        fov_deg: horizontal field of view from EXIF (:func:`exif_fov_deg`), or None.
        alpha: ``(H, W)`` float32 alpha of an RGBA photo in [0, 1], or None.
        notes: one line each about what was done to read it (turned upright, 16 bits taken at
            8, alpha dropped).
        radiance: True for an ``.exr`` / ``.hdr`` photo: ``image`` is then linear radiance (float32, any
            scale, non-negative), not display values.
    """

    image: np.ndarray
    fov_deg: float | None = None
    alpha: np.ndarray | None = None
    notes: list[str] = field(default_factory=list)
    radiance: bool = False


_EXIF_ORIENTATION, _EXIF_IFD = 0x0112, 0x8769
_FOCAL_LENGTH, _FOCAL_35MM = 0x920A, 0xA405
_FOCAL_PLANE_X_RES, _FOCAL_PLANE_UNIT = 0xA20E, 0xA210
_UNIT_MM = {2: 25.4, 3: 10.0, 4: 1.0, 5: 0.001}  # inch, cm, mm, micrometre
_FULL_FRAME_DIAGONAL_MM = math.hypot(36.0, 24.0)


def exif_fov_deg(exif: Any, width: int, height: int) -> float | None:
    """The horizontal field of view (degrees) of an upright ``width x height`` photo from its EXIF.

    From ``FocalLengthIn35mmFilm`` (the focal length a 36 x 24 mm frame would need for the same
    *diagonal* angle: ``tan(d/2) = 43.27 / (2 f35)``, then the horizontal part of that diagonal),
    else from ``FocalLength`` with the sensor width ``FocalPlaneXResolution`` implies. None when
    neither is there or the values are not usable.
    """
    if exif is None:
        return None
    sub = exif.get_ifd(_EXIF_IFD) if hasattr(exif, "get_ifd") else {}
    get = lambda tag: sub.get(tag, exif.get(tag))  # noqa: E731 - EXIF tags live in either IFD
    try:
        f35 = float(get(_FOCAL_35MM) or 0)
        if f35 > 0:
            half_diag = math.atan(_FULL_FRAME_DIAGONAL_MM / (2 * f35))
            return math.degrees(2 * math.atan(math.tan(half_diag) * width / math.hypot(width, height)))
        f = float(get(_FOCAL_LENGTH) or 0)
        xres, unit = float(get(_FOCAL_PLANE_X_RES) or 0), int(get(_FOCAL_PLANE_UNIT) or 2)
        if f > 0 and xres > 0 and unit in _UNIT_MM:
            # FocalPlaneXResolution is per unit along the sensor's long side as recorded (landscape).
            sensor_mm = max(width, height) / xres * _UNIT_MM[unit]
            return math.degrees(2 * math.atan(sensor_mm * width / max(width, height) / (2 * f)))
    except (TypeError, ValueError, ZeroDivisionError):
        return None
    return None


def _png_bit_depth(path: Path) -> int:
    """The bit depth in a PNG's header (PIL reads 16-bit RGB as 8-bit RGB without saying so)."""
    with open(path, "rb") as f:
        head = f.read(25)
    return head[24] if len(head) == 25 and head[12:16] == b"IHDR" else 8


def read_photo(path: str | os.PathLike) -> Photo:
    """Read a PNG/JPEG photo upright, with its field of view, for relighting; an ``.exr`` or ``.hdr`` photo as
    linear radiance (``Photo.radiance``).

    Turned by its EXIF orientation (a phone's portrait photo is stored sideways). 16-bit
    photos are taken at 8 bits, RGBA and grey-with-alpha photos give their alpha separately (a mask
    hint; the colour is read as it is), a grey-scale photo's one channel is read as three equal
    ones; each such step leaves a note. Palette and bilevel images are refused with a
    ``ValueError`` naming the mode.
    """
    from PIL import Image, ImageOps, UnidentifiedImageError

    p = Path(path)
    if not p.is_file():
        raise ValueError(f"image {str(p)!r} does not exist")
    if p.suffix.lower() in (".exr", ".hdr"):  # a render or an HDR photo: linear radiance, no EXIF
        rgb = read_radiance(p)  # float32 (H, W, 3), finite, non-negative, or a one-line ValueError
        return Photo(np.ascontiguousarray(rgb, dtype=np.float32), None, None,
                     ["linear radiance (an EXR or HDR photo): relit as radiance"], radiance=True)
    notes: list[str] = []
    try:
        with Image.open(p) as im:
            im.load()
            exif = im.getexif()
            if exif.get(_EXIF_ORIENTATION, 1) not in (1, None):
                notes.append(f"turned upright by its EXIF orientation ({exif.get(_EXIF_ORIENTATION)})")
            bits16 = im.mode.startswith("I;16") or (im.format == "PNG" and _png_bit_depth(p) == 16)
            up = ImageOps.exif_transpose(im)
            mode = up.mode
            alpha = None
            if mode in ("RGBA", "LA") or (mode == "P" and "transparency" in up.info):
                if mode == "P":
                    raise ValueError(f"{str(p)!r} is a {mode!r} image; an RGB colour photo is needed")
                alpha = np.asarray(up.getchannel("A"), dtype=np.float32) / 255.0
                notes.append("its alpha channel is read apart (a mask hint), not as colour")
                up = up.convert("RGB" if mode == "RGBA" else "L")
            if up.mode in ("L", "I", "I;16", "I;16B", "I;16L"):
                grey = np.asarray(up)
                if grey.dtype != np.uint8:  # 16-bit grey comes as integers up to 65535
                    grey = np.round(np.clip(grey.astype(np.float64), 0, 65535) / 257.0).astype(np.uint8)
                notes.append("a grey-scale photo: its one channel is read as three equal ones")
                arr = np.repeat(grey[..., None], 3, axis=-1)
            elif up.mode == "RGB":
                arr = np.asarray(up)
            else:
                raise ValueError(f"{str(p)!r} is a {mode!r} image; an RGB colour photo is needed")
            if bits16:
                notes.append("16-bit samples are taken at 8 bits")
            width, height = up.size
    except (UnidentifiedImageError, OSError) as err:
        raise ValueError(f"cannot read {str(p)!r} as an image: {err}") from None
    return Photo(arr.astype(np.float32) / 255.0, exif_fov_deg(exif, width, height), alpha, notes)


def read_mask(path: str | os.PathLike, shape: tuple[int, int] | None = None) -> np.ndarray:
    """Read a mask PNG as bool ``(H, W)``: white (>= 128) is on, black off.

    Single-channel (grey) or RGB with three equal channels; anything else (a colour photo given
    as a mask) is refused with a ``ValueError``, as is an alpha channel that is not opaque, and, with
    ``shape`` (the photo's ``(H, W)``), a mask of another size.
    """
    from PIL import Image, UnidentifiedImageError

    p = Path(path)
    if not p.is_file():
        raise ValueError(f"mask {str(p)!r} does not exist")
    try:
        with Image.open(p) as im:
            im.load()
            if im.mode in ("L", "1", "I", "I;16", "P"):
                arr = np.asarray(im.convert("L"))
            elif im.mode in ("RGB", "RGBA", "LA"):
                rgb = np.asarray(im.convert("RGB")).astype(np.int16)
                if np.abs(rgb - rgb[..., :1]).max() > 2:  # JPEG noise is allowed, colour is not
                    raise ValueError(f"mask {str(p)!r} is a colour image; a mask is grey-scale (white = sky)")
                arr = rgb[..., 0]
            else:
                raise ValueError(f"mask {str(p)!r} is a {im.mode!r} image; a mask is grey-scale (white = sky)")
    except (UnidentifiedImageError, OSError) as err:
        raise ValueError(f"cannot read {str(p)!r} as an image: {err}") from None
    if shape is not None and arr.shape != tuple(shape):
        raise ValueError(f"mask {str(path)!r} is {arr.shape[1]}x{arr.shape[0]}, the photo {shape[1]}x{shape[0]}")
    return arr >= 128


PNG_COMPRESS_LEVEL = 1
"""zlib level of :func:`write_png`. A PNG is lossless at any level; only size and time change. The relit rocket.jpg
at 4000 x 2669 (2-core AMD EPYC, loaded, median of 3): level 1 1.17 s and 8.8 MB, level 3 1.84 s and 8.2 MB,
level 6 (Pillow's default, used before) 4.60 s and 7.0 MB: level 1 saves three quarters of the time for a quarter
more bytes."""


def write_png(path: str | os.PathLike, image: Array) -> None:
    """Write display values ``(H, W)``, ``(H, W, 1)``, ``(H, W, 3)`` or with alpha ``(H, W, 2)`` (grey) /
    ``(H, W, 4)`` (RGB) in [0, 1] as an 8-bit PNG (rounded, clipped; zlib level :data:`PNG_COMPRESS_LEVEL`;
    encoded by :func:`physrelight.png.encode_png`)."""
    from physrelight.png import encode_png

    t, _ = to_tensor(image, "image")
    t = t.detach().cpu()
    if t.ndim not in (2, 3) or (t.ndim == 3 and t.shape[-1] not in (1, 2, 3, 4)):
        raise ValueError(f"image must have shape (H, W) or (H, W, C) with C in 1-4, got {tuple(t.shape)}")
    if not bool(torch.isfinite(t).all()):
        raise ValueError("image holds NaN or inf")
    if t.ndim == 3 and t.shape[-1] == 1:
        t = t[..., 0]
    # by torch's kernels (on its threads): the same bytes as numpy's round-half-to-even of x * 255 in x's dtype
    u8 = torch.round(t * 255.0).clamp_(0, 255).to(torch.uint8).numpy()
    data = encode_png(u8, PNG_COMPRESS_LEVEL)  # on several threads (physrelight.png)
    with atomic_path(path, ".png") as tmp:
        tmp.write_bytes(data)


def write_json(path: str | os.PathLike, data: Any) -> None:
    """Write JSON (sorted keys, 2-space indent) atomically; numpy scalars/arrays are converted."""

    def default(o: Any) -> Any:
        if isinstance(o, np.ndarray):
            return o.tolist()
        if isinstance(o, np.generic):
            return o.item()
        if isinstance(o, Path):
            return str(o)
        raise TypeError(f"cannot serialise {type(o).__name__} to JSON")

    text = json.dumps(data, indent=2, sort_keys=True, default=default) + "\n"
    with atomic_path(path, ".json") as tmp:
        tmp.write_text(text)


def read_json(path: str | os.PathLike) -> Any:
    """Read a JSON file, with a ``ValueError`` naming the file when it is missing or broken."""
    p = Path(path)
    try:
        return json.loads(p.read_text())
    except FileNotFoundError:
        raise ValueError(f"{str(p)!r} does not exist") from None
    except json.JSONDecodeError as err:
        raise ValueError(f"{str(p)!r} is not valid JSON: {err}") from None
