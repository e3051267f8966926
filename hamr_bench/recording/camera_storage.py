"""How camera frames are kept in a recording (format 2): the user's choice, sized by default for keeping.

Modes (`--camera-storage`, docs/log-format.md "Camera storage"):
- `roi` (default): every frame's region of interest, a `roi_px` square around the tracked marker, on `/camera/roi`
  (`foxglove.RawImage`) with its top-left pixel on `/camera/roi/origin` (`x0_px`, `y0_px`, full-frame pixels),
  plus one full frame every `full_frame_interval_s` on `/camera/image` (`foxglove.RawImage`), both in compressed
  chunks. A frame whose marker was not found is kept whole on `/camera/image`, so nothing tracking would need is
  lost. Lossless within the region: re-tracking the stored regions gives the positions tracked live (tested).
- `full`: every full frame on `/camera/image` as `foxglove.RawImage` in stored (uncompressed) chunks: the format-1
  behaviour, the largest (4.5 MB per recorded second at 320x240 and 60 fps) and the cheapest in CPU.
- `png`: every full frame as a lossless `foxglove.CompressedImage` (PNG, zlib level 1): about a third of `full`
  on the simulated camera, at ~5 ms of CPU a frame (too slow for 100 fps at 640x480 on a small machine).
- `none`: no pixels at all, only the tracked displacement.

The marker position comes from the caller (the runner tracks each frame before writing it); tracking itself never
depends on how frames are stored. Whatever the mode, the marker is also drawn for Foxglove on
`/camera/annotations` (`foxglove.ImageAnnotations`, a circle in full-frame pixels, one per tracked frame).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hamr_bench.errors import ConfigError

MODES = ("roi", "full", "png", "none")
DEFAULT_ROI_PX = 64
DEFAULT_FULL_FRAME_INTERVAL_S = 1.0
_TIME_TOLERANCE_S = 1e-9  # frame times are sums of periods: 0.2 + 0.1 must count as 0.3
PNG_LEVEL = 1  # zlib level: 1 is within 10 % of the best size on camera frames for a quarter of level 6's time


@dataclass(frozen=True)
class CameraStorage:
    """What `roi` keeps; see the module docstring."""

    mode: str = "roi"
    roi_px: int = DEFAULT_ROI_PX
    full_frame_interval_s: float = DEFAULT_FULL_FRAME_INTERVAL_S

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ConfigError(f"camera storage {self.mode!r}: expected one of {', '.join(MODES)}")
        if not 8 <= self.roi_px <= 1024:
            raise ConfigError(f"camera storage: region of interest {self.roi_px} px outside [8, 1024]")
        if not (math.isfinite(self.full_frame_interval_s) and self.full_frame_interval_s > 0):
            raise ConfigError(f"camera storage: full-frame interval {self.full_frame_interval_s!r} s must be > 0")

    @classmethod
    def parse(cls, text: str) -> CameraStorage:
        """`roi`, `roi:SIZE_PX`, `roi:SIZE_PX:FULL_FRAME_INTERVAL_S`, `full`, `png` or `none`."""
        mode, *rest = text.strip().split(":")
        if rest and mode != "roi":
            raise ConfigError(f"--camera-storage {text!r}: only `roi` takes options (roi:SIZE_PX[:INTERVAL_S])")
        if len(rest) > 2:
            raise ConfigError(f"--camera-storage {text!r}: expected roi:SIZE_PX[:INTERVAL_S]")
        try:
            roi_px = int(rest[0]) if rest else DEFAULT_ROI_PX
            interval_s = float(rest[1]) if len(rest) > 1 else DEFAULT_FULL_FRAME_INTERVAL_S
        except ValueError:
            raise ConfigError(f"--camera-storage {text!r}: SIZE_PX must be an integer and INTERVAL_S a number") \
                from None
        return cls(mode, roi_px, interval_s)

    def describe(self) -> str:
        if self.mode == "roi":
            return f"roi:{self.roi_px}:{self.full_frame_interval_s:g}"
        return self.mode


@dataclass(frozen=True)
class FrameWrite:
    """One image the recorder writes for a camera frame."""

    topic: str
    image: np.ndarray | bytes  # pixels (raw), or PNG bytes already encoded
    format: str  # raw | png
    stored: bool  # in stored (uncompressed) chunks


class FramePlanner:
    """Decides, frame by frame, what of it to keep (stateful: when the last full frame was kept)."""

    def __init__(self, storage: CameraStorage, full_topic: str, roi_topic: str) -> None:
        self.storage = storage
        self._full_topic = full_topic
        self._roi_topic = roi_topic
        self._next_full_s = -math.inf

    def plan(self, time_s: float, image: np.ndarray, marker_px: tuple[float, float] | None,
             ) -> tuple[list[FrameWrite], tuple[int, int] | None]:
        """The images to write for this frame, and the region's origin (x0, y0) when a region is among them."""
        mode = self.storage.mode
        if mode == "none":
            return [], None
        if mode == "full":
            return [FrameWrite(self._full_topic, image, "raw", True)], None
        if mode == "png":
            return [FrameWrite(self._full_topic, encode_png(image), "png", True)], None
        writes: list[FrameWrite] = []
        origin = region_origin(image.shape, marker_px, self.storage.roi_px)
        if origin is None or time_s >= self._next_full_s - _TIME_TOLERANCE_S:
            # A frame without a marker fix is kept whole (nothing a re-analysis would need is lost).
            writes.append(FrameWrite(self._full_topic, image, "raw", False))
            if origin is not None:
                self._next_full_s = time_s + self.storage.full_frame_interval_s
        if origin is not None:
            x0, y0 = origin
            size = self.storage.roi_px
            writes.append(FrameWrite(self._roi_topic, image[y0:y0 + size, x0:x0 + size], "raw", False))
        return writes, origin


def encode_png(image: np.ndarray) -> bytes:
    """Lossless PNG with real compression (zlib level `PNG_LEVEL`), through OpenCV."""
    import cv2

    ok, buffer = cv2.imencode(".png", image, [cv2.IMWRITE_PNG_COMPRESSION, PNG_LEVEL])
    if not ok:
        raise ConfigError(f"OpenCV could not encode a frame of shape {image.shape} as PNG")
    return buffer.tobytes()


def marker_annotation_payload(timestamp_ns: int, marker_px: tuple[float, float], diameter_px: float) -> bytes:
    """`foxglove.ImageAnnotations` bytes: one circle around the tracked marker (full-frame pixels)."""
    from foxglove_schemas_protobuf.ImageAnnotations_pb2 import ImageAnnotations

    msg = ImageAnnotations()
    circle = msg.circles.add(diameter=diameter_px, thickness=2.0)
    circle.timestamp.FromNanoseconds(int(timestamp_ns))
    circle.position.x, circle.position.y = float(marker_px[0]), float(marker_px[1])
    circle.outline_color.g, circle.outline_color.a = 1.0, 1.0
    return msg.SerializeToString()


def region_origin(shape: tuple[int, ...], marker_px: tuple[float, float] | None, size: int,
                  ) -> tuple[int, int] | None:
    """Top-left pixel of the `size` square centred on the marker, moved inside the image; None without a finite
    marker position or when the image is smaller than the square."""
    if marker_px is None:
        return None
    x, y = marker_px
    height, width = shape[:2]
    if not (math.isfinite(x) and math.isfinite(y)) or width < size or height < size:
        return None
    half = size // 2
    x0 = min(max(int(round(x)) - half, 0), width - size)
    y0 = min(max(int(round(y)) - half, 0), height - size)
    return x0, y0

