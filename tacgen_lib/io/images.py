"""PNG bytes <-> uint8 RGB arrays, the image encoding of every corpus edge (docs/layout.md, Corpus edges).

Images travel between rules as PNG bytes in `binary` columns. PNG is lossless, so a frame
decoded from an edge equals the array that was encoded, and encoding is deterministic, so the
same frame always gives the same bytes (edges stay bit-for-bit reproducible).
"""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["encode_png", "decode_png"]


def encode_png(image: np.ndarray, *, compression: int = 3) -> bytes:
    """Encode an (H, W, 3) uint8 RGB (or (H, W) grey) array as PNG bytes."""
    if image.dtype != np.uint8:
        raise TypeError(f"encode_png: expected uint8 pixels, got {image.dtype}")
    if image.ndim == 3 and image.shape[2] == 3:
        bgr = np.ascontiguousarray(image[:, :, ::-1])
    elif image.ndim == 2:
        bgr = np.ascontiguousarray(image)
    else:
        raise ValueError(f"encode_png: expected (H, W, 3) or (H, W), got shape {image.shape}")
    ok, buf = cv2.imencode(".png", bgr, [cv2.IMWRITE_PNG_COMPRESSION, compression])
    if not ok:
        raise RuntimeError("encode_png: OpenCV failed to encode the frame")
    return buf.tobytes()


def decode_png(data: bytes, *, where: str = "") -> np.ndarray:
    """Decode PNG (or JPEG) bytes to an (H, W, 3) uint8 RGB array.

    `where` names the file/sample for the error message when the bytes are not an image.
    """
    arr = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_COLOR)
    if arr is None:
        raise ValueError(f"{where or 'decode_png'}: bytes are not a decodable image")
    return np.ascontiguousarray(arr[:, :, ::-1])
