"""Turning camera frames (numpy arrays) into the bytes of a `foxglove.RawImage` or `foxglove.CompressedImage`, and
back.

Raw (the recorder's default) is the frame's own bytes with its size and pixel encoding: no encoding work at all,
which matters at tens of frames a second on a bench whose whole budget is about a millisecond a frame.

PNG is written here directly, with the image rows stored (deflate level 0, no PNG filter): lossless and about 0.3 ms
for a 640x480 frame, where a compressing PNG encoder costs 2.5-6 ms, more than the recorder's whole CPU budget at
100 fps. The file's chunk compression then does the squeezing. JPEG (lossy, small) goes through OpenCV.
"""

from __future__ import annotations

import struct
import zlib

import numpy as np

from hamr_bench.errors import RecordingError

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
# PNG colour types: 0 grey, 2 RGB.
_PNG_COLOUR = {1: 0, 3: 2}


def _png_chunk(tag: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(data, zlib.crc32(tag)))


def encode_png_stored(image: np.ndarray) -> bytes:
    """A valid PNG of a grey (H, W) or RGB (H, W, 3) uint8/uint16 image, rows stored uncompressed."""
    if image.ndim == 2:
        channels = 1
    elif image.ndim == 3 and image.shape[2] == 3:
        channels = 3
    else:
        raise RecordingError(f"image of shape {image.shape} cannot be written as PNG (expected HxW or HxWx3)")
    if image.dtype == np.uint8:
        bit_depth = 8
        pixels = image
    elif image.dtype == np.uint16:
        bit_depth = 16
        pixels = image.astype(">u2", copy=False)  # PNG stores 16-bit samples big-endian
    else:
        raise RecordingError(f"image dtype {image.dtype} cannot be written as PNG (expected uint8 or uint16)")
    height, width = image.shape[:2]
    row_bytes = width * channels * pixels.dtype.itemsize
    raw = np.empty((height, row_bytes + 1), dtype=np.uint8)
    raw[:, 0] = 0  # filter type 0 (none) on every row
    raw[:, 1:] = np.ascontiguousarray(pixels).view(np.uint8).reshape(height, row_bytes)
    header = struct.pack(">IIBBBBB", width, height, bit_depth, _PNG_COLOUR[channels], 0, 0, 0)
    idat = zlib.compress(raw.data, 0)
    # The IDAT chunk is written in pieces (length, tag, data, CRC) so that the frame's bytes are copied once, by
    # the join, rather than once per concatenation.
    return b"".join(
        (
            _PNG_SIGNATURE,
            _png_chunk(b"IHDR", header),
            struct.pack(">I", len(idat)),
            b"IDAT",
            idat,
            struct.pack(">I", zlib.crc32(idat, zlib.crc32(b"IDAT"))),
            _png_chunk(b"IEND", b""),
        )
    )


def encode_image(image: np.ndarray, image_format: str) -> bytes:
    if image_format == "png":
        return encode_png_stored(image)
    if image_format in ("jpeg", "jpg"):
        import cv2

        ok, buffer = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 95])
        if not ok:
            raise RecordingError(f"OpenCV could not encode an image of shape {image.shape} as JPEG")
        return buffer.tobytes()
    raise RecordingError(f"image format {image_format!r} is not supported for arrays (use 'png' or 'jpeg')")


# foxglove.RawImage pixel encodings (ROS conventions) of the arrays a camera driver gives: grey 8/16 bit, OpenCV BGR.
_RAW_ENCODING: dict[tuple[int, np.dtype], str] = {
    (2, np.dtype(np.uint8)): "mono8", (2, np.dtype(np.uint16)): "mono16",
    (3, np.dtype(np.uint8)): "bgr8", (3, np.dtype(np.uint16)): "bgr16"}
_RAW_LAYOUT = {name: (dtype, ndim) for (ndim, dtype), name in _RAW_ENCODING.items()}


def raw_image_fields(image: np.ndarray) -> tuple[int, int, str, int, bytes]:
    """(width, height, encoding, step, data) of a `foxglove.RawImage` holding `image` (grey HxW or BGR HxWx3, uint8
    or uint16; 16-bit samples little-endian, as ROS `mono16` on every common platform)."""
    if image.ndim == 3 and image.shape[2] != 3:
        encoding = None
    else:
        encoding = _RAW_ENCODING.get((image.ndim, image.dtype.newbyteorder("=")))
    if encoding is None:
        raise RecordingError(f"image of shape {image.shape} and dtype {image.dtype} cannot be stored raw "
                             "(expected HxW or HxWx3, uint8 or uint16)")
    height, width = image.shape[:2]
    pixels = image.astype(image.dtype.newbyteorder("<"), copy=False)
    data = np.ascontiguousarray(pixels).tobytes()
    return width, height, encoding, len(data) // height if height else 0, data


def decode_raw_image(data: bytes, width: int, height: int, encoding: str, step: int) -> np.ndarray:
    """Pixels of a `foxglove.RawImage` (the encodings `raw_image_fields` writes)."""
    layout = _RAW_LAYOUT.get(encoding)
    if layout is None:
        raise RecordingError(f"raw image encoding {encoding!r} is not supported ({', '.join(_RAW_LAYOUT)})")
    dtype, ndim = layout
    row_bytes = width * (3 if ndim == 3 else 1) * dtype.itemsize
    if step < row_bytes or len(data) < step * height:
        raise RecordingError(f"raw image {width}x{height} {encoding}: step {step} and {len(data)} data bytes "
                             "do not hold its rows")
    rows = np.frombuffer(data, dtype=np.uint8, count=step * height).reshape(height, step)[:, :row_bytes]
    pixels = rows.copy().view(dtype.newbyteorder("<")).astype(dtype, copy=False)
    return pixels.reshape((height, width, 3) if ndim == 3 else (height, width))


def decode_image(data: bytes) -> np.ndarray:
    """Pixels of PNG or JPEG bytes (grey stays 2-D; colour comes back in OpenCV's BGR order)."""
    import cv2

    pixels = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
    if pixels is None:
        raise RecordingError("image bytes could not be decoded (not PNG/JPEG, or corrupted)")
    return pixels
