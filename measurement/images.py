"""Reading images of any common format into grayscale arrays, with errors that name the file."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from .errors import ImageError

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp")


def decode_image(data: bytes, name: str) -> np.ndarray:
    """Decode encoded image bytes to a grayscale array.

    Returns (H, W) uint8 or uint16, keeping the bit depth of the file. Colour images are converted
    with OpenCV's luma weights. Raises ImageError naming ``name`` when the bytes are not a complete image.
    """
    if not data:
        raise ImageError(f"{name}: file is empty")
    if _looks_truncated(data, name):
        raise ImageError(f"{name}: image file is truncated")
    buf = np.frombuffer(data, dtype=np.uint8)
    img = cv2.imdecode(buf, cv2.IMREAD_UNCHANGED | cv2.IMREAD_ANYDEPTH)
    if img is None or img.size == 0:
        raise ImageError(f"{name}: not a readable image (PNG, JPEG, TIFF or BMP expected)")
    return to_gray(img, name)


def read_image(path: str | Path) -> np.ndarray:
    """Read an image file to a grayscale (H, W) uint8/uint16 array; ImageError names the file."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ImageError(f"{path.name}: cannot read ({exc.strerror})") from exc
    return decode_image(data, path.name)


def to_gray(img: np.ndarray, name: str = "image") -> np.ndarray:
    """Convert (H, W), (H, W, 3) or (H, W, 4) arrays of uint8/uint16/float to grayscale, keeping uint dtypes."""
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    if img.ndim == 3 and img.shape[2] in (3, 4):
        code = cv2.COLOR_BGR2GRAY if img.shape[2] == 3 else cv2.COLOR_BGRA2GRAY
        img = cv2.cvtColor(img, code)
    if img.ndim != 2:
        raise ImageError(f"{name}: expected a 2-D gray or 3-channel colour image, got shape {img.shape}")
    if img.dtype in (np.uint8, np.uint16):
        return img
    if np.issubdtype(img.dtype, np.floating):
        scale = 255.0 if float(np.nanmax(img)) <= 1.0 else 1.0
        return np.clip(img * scale, 0, 255).astype(np.uint8)
    return np.clip(img, 0, 65535).astype(np.uint16)


def sample_bits(image: np.ndarray) -> int:
    """How many bits a 16-bit frame's samples use: 8, 10, 12, 14 or 16, the fewest that hold its largest
    value (a camera's 10-, 12- or 14-bit samples are often written unshifted into 16-bit PNG or TIFF files;
    the paper's camera gives Mono8 or Mono12). 8 for an 8-bit frame."""
    if image.dtype != np.uint16 or image.size == 0:
        return 8
    used = int(image.max()).bit_length()
    return min(max(used + used % 2, 8), 16)


def to_float(img: np.ndarray, bits: int | None = None) -> np.ndarray:
    """Scale an 8- or 16-bit gray image to float32 in the 0..255 range: 16-bit from the ``bits`` its samples
    use (``sample_bits`` of the image by default; a full 16-bit image is divided by 257)."""
    if img.dtype == np.uint16:
        bits = sample_bits(img) if bits is None else bits
        return img.astype(np.float32) * np.float32(255.0 / float(2**bits - 1))
    if img.dtype == np.float32:
        return img
    return img.astype(np.float32)


def _looks_truncated(data: bytes, name: str) -> bool:
    """OpenCV decodes some truncated PNG/JPEG files silently (grey fill); check their end markers."""
    if data[:8] == b"\x89PNG\r\n\x1a\n":
        return b"IEND" not in data[-16:]
    if data[:2] == b"\xff\xd8":
        return b"\xff\xd9" not in data[-4:].rstrip(b"\x00")
    return False
