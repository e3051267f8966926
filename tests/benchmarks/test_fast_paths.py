"""Fast paths added for speed (docs/performance.md) give exactly what the slow reference gives: the recorder's
hand-built foxglove.CompressedImage and foxglove.RawImage bytes against protobuf's own serialiser, and the stored PNG
against a decoder."""

from __future__ import annotations

import cv2
import numpy as np
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
from hypothesis import given, settings
from hypothesis import strategies as st

from hamr_bench.recording.images import encode_png_stored
from hamr_bench.recording.image_payloads import compressed_image_payload, raw_image_payload


@settings(max_examples=300, deadline=None)
@given(st.integers(-(2**62), 2**62), st.text(max_size=12), st.sampled_from(["png", "jpeg", ""]),
       st.binary(max_size=600))
def test_compressed_image_bytes_match_protobuf(timestamp_ns, frame_id, image_format, data):
    msg = CompressedImage(frame_id=frame_id, format=image_format, data=data)
    msg.timestamp.FromNanoseconds(timestamp_ns)
    assert compressed_image_payload(timestamp_ns, frame_id, image_format, data) == msg.SerializeToString()


@settings(max_examples=300, deadline=None)
@given(st.integers(-(2**62), 2**62), st.text(max_size=12), st.integers(0, 2**32 - 1), st.integers(0, 2**32 - 1),
       st.sampled_from(["mono8", "mono16", "bgr8", ""]), st.integers(0, 2**32 - 1), st.binary(max_size=600))
def test_raw_image_bytes_match_protobuf(timestamp_ns, frame_id, width, height, encoding, step, data):
    msg = RawImage(frame_id=frame_id, width=width, height=height, encoding=encoding, step=step, data=data)
    msg.timestamp.FromNanoseconds(timestamp_ns)
    assert raw_image_payload(timestamp_ns, frame_id, width, height, encoding, step, data) == msg.SerializeToString()


def test_stored_png_decodes_to_the_same_pixels():
    rng = np.random.default_rng(0)
    for image in (rng.integers(0, 256, (48, 64), dtype=np.uint8), rng.integers(0, 65536, (30, 20), dtype=np.uint16),
                  rng.integers(0, 256, (10, 12, 3), dtype=np.uint8)):
        back = cv2.imdecode(np.frombuffer(encode_png_stored(image), np.uint8), cv2.IMREAD_UNCHANGED)
        expected = image[:, :, ::-1] if image.ndim == 3 else image  # OpenCV decodes colour as BGR
        assert back.dtype == image.dtype and np.array_equal(back, expected)
