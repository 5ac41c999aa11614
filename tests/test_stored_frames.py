"""Learned policies see live frames as a collection stores them (JPEG at the training data's
quality), and snapshots say which quality that was."""

from __future__ import annotations

import numpy as np

from awda_bench.data.recorder import encode_jpeg
from awda_bench.data.trajectory_file import (
    DEFAULT_JPEG_QUALITY,
    as_stored,
    decode_jpeg,
    trained_jpeg_quality,
)


def test_as_stored_is_the_collections_round_trip_at_any_batch_shape() -> None:
    rng = np.random.default_rng(0)
    frames = rng.integers(0, 256, size=(2, 3, 24, 32, 3), dtype=np.uint8)
    stored = as_stored(frames, 90)
    assert stored.shape == frames.shape and stored.dtype == np.uint8
    want = decode_jpeg(np.frombuffer(encode_jpeg(frames[1, 2], 90), np.uint8))
    np.testing.assert_array_equal(stored[1, 2], want)
    assert np.abs(stored.astype(int) - frames).mean() > 1  # noise does not survive JPEG intact
    coarse = as_stored(frames, 20)
    assert np.abs(coarse.astype(int) - frames).mean() > np.abs(stored.astype(int) - frames).mean()


def test_the_training_record_gives_the_quality() -> None:
    assert trained_jpeg_quality({"data": {"jpeg_quality": 75}}) == 75
    assert trained_jpeg_quality({"data": {"fingerprint": "x"}}) == DEFAULT_JPEG_QUALITY
    assert trained_jpeg_quality(None) == DEFAULT_JPEG_QUALITY
