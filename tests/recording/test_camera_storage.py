"""Camera storage (format 2): what each mode keeps, and that the default (`roi`) keeps what tracking needs.

The tracking test runs the simulated free-displacement protocol twice with the same seed, frames kept whole
(`full`, format 1's behaviour) and as regions (`roi`): the displacement tracked live is identical, and tracking the
stored regions gives bit for bit what tracking the same full frames gives from the same starting point (the
tracker's window lies inside the region)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hamr_bench.errors import ConfigError
from hamr_bench.recording import Recorder, RecordingReader, schemas
from hamr_bench.recording.camera_storage import CameraStorage, region_origin


def frames(n: int, rng: np.random.Generator):
    for k in range(n):
        image = rng.integers(0, 6, size=(120, 160), dtype=np.uint8)
        x, y = 40.0 + k * 3.3, 60.0 + k * 0.7
        image[int(y) - 2:int(y) + 3, int(x) - 2:int(x) + 3] = 250
        yield k * 0.01, image, (x, y)


def write(path: Path, storage: CameraStorage, n: int = 40, lose_marker_at: int = -1):
    rng = np.random.default_rng(1)
    kept = []
    with Recorder(path, camera=storage) as rec:
        for k, (t, image, marker) in enumerate(frames(n, rng)):
            rec.write_image("/camera/image", t, image, marker_px=None if k == lose_marker_at else marker)
            kept.append((t, image, marker))
    return kept


def test_roi_keeps_the_region_every_frame_and_a_whole_frame_per_interval(tmp_path):
    path = tmp_path / "roi.mcap"
    kept = write(path, CameraStorage("roi", roi_px=32, full_frame_interval_s=0.1), lose_marker_at=17)
    r = RecordingReader(path)
    regions = list(r.images("/camera/roi"))
    assert len(regions) == len(kept) - 1  # every frame but the one without a marker fix
    with_marker = [f for k, f in enumerate(kept) if k != 17]
    for region, (t, image, marker) in zip(regions, with_marker, strict=True):
        x0, y0 = region.origin_px
        assert (x0, y0) == region_origin(image.shape, marker, 32)
        np.testing.assert_array_equal(region.pixels(), image[y0:y0 + 32, x0:x0 + 32])
        assert abs(region.time_s - t) < 1e-9
    whole = list(r.images("/camera/image"))
    times = [round(f.time_s, 6) for f in whole]
    assert times == [0.0, 0.1, 0.17, 0.2, 0.3]  # one per 0.1 s, plus the frame whose marker was lost
    np.testing.assert_array_equal(whole[2].pixels(), kept[17][1])
    annotations = r.topics()["/camera/annotations"]
    assert annotations.schema_name == schemas.ANNOTATIONS_SCHEMA and annotations.message_count == len(kept) - 1
    assert r.metadata()["recording"]["camera_storage"] == "roi:32:0.1"


@pytest.mark.parametrize("mode", ["full", "png"])
def test_full_and_png_keep_every_frame_losslessly(tmp_path, mode):
    path = tmp_path / f"{mode}.mcap"
    kept = write(path, CameraStorage(mode), n=12)
    r = RecordingReader(path)
    whole = list(r.images("/camera/image"))
    assert [f.format for f in whole] == ["raw" if mode == "full" else "png"] * 12
    for frame, (_, image, _) in zip(whole, kept, strict=True):
        np.testing.assert_array_equal(frame.pixels(), image)
    assert "/camera/roi" not in r.topics()


def test_none_keeps_no_pixels_but_still_draws_the_marker(tmp_path):
    path = tmp_path / "none.mcap"
    write(path, CameraStorage("none"), n=5)
    topics = RecordingReader(path).topics()
    assert "/camera/image" not in topics and "/camera/roi" not in topics
    assert topics["/camera/annotations"].message_count == 5


@pytest.mark.parametrize("text", ["roi:abc", "full:3", "jpeg", "roi:4", "roi:64:0", "roi:1:2:3"])
def test_bad_camera_storage_is_one_clear_error(text):
    with pytest.raises(ConfigError, match="camera storage|--camera-storage"):
        CameraStorage.parse(text)


def test_region_stays_inside_the_image():
    assert region_origin((100, 200), (2.0, 98.0), 32) == (0, 68)
    assert region_origin((100, 200), (199.4, 50.2), 32) == (168, 34)
    assert region_origin((100, 200), (float("nan"), 1.0), 32) is None
    assert region_origin((20, 200), (10.0, 10.0), 32) is None  # the image is smaller than the region


@pytest.mark.slow
def test_tracking_is_unchanged_by_how_frames_are_kept(tmp_path):
    from drivers.tracking import MarkerTracker
    from hamr_bench.protocols.session import RunRequest, run_protocol

    paths = {}
    for mode in ("full", "roi"):
        paths[mode] = tmp_path / f"{mode}.mcap"
        result = run_protocol(RunRequest(
            protocol="free-displacement", out=paths[mode], seed=5, camera_storage=CameraStorage(mode),
            set_options=["voltages_V=250", "repetitions=1"]))
        assert result.ok, result.reason
    full, roi = RecordingReader(paths["full"]), RecordingReader(paths["roi"])
    for topic in ("/camera/displacement", "/force", "/amplifier/drive/command"):
        a, b = full.scalars(topic), roi.scalars(topic)
        assert all(np.array_equal(a[k], b[k], equal_nan=True) for k in a), topic
    live = full.scalars("/camera/displacement")
    regions = list(roi.images("/camera/roi"))
    assert len(regions) == len(live["time_s"])
    tracker = MarkerTracker(sigma_px=2.0)
    whole_frames = full.images("/camera/image")
    differences = []
    for k, (region, frame) in enumerate(zip(regions, whole_frames, strict=False)):
        x0, y0 = region.origin_px
        guess = (float(live["x_px"][k]), float(live["y_px"][k]))
        from_full = tracker.locate(frame.pixels(), guess_px=guess)
        from_region = tracker.locate(region.pixels(), guess_px=(guess[0] - x0, guess[1] - y0))
        differences.append((from_region.x_px + x0 - from_full.x_px, from_region.y_px + y0 - from_full.y_px))
    assert np.max(np.abs(differences)) < 1e-9  # the same up to the rounding of the coordinate shift
    assert roi.path.stat().st_size < full.path.stat().st_size / 5
