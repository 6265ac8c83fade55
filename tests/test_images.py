"""Image files of any depth read as the network takes them (vfactor.images): 8-bit RGB."""

import json

import cv2
import numpy as np
import pytest

from vfactor.errors import SceneError
from vfactor.images import read_rgb, to_uint8

RNG = np.random.default_rng(7)
BGR8 = RNG.integers(0, 256, (36, 52, 3), dtype=np.uint8)
RGB8 = BGR8[..., ::-1]


def at_bits(image8: np.ndarray, bits: int) -> np.ndarray:
    """An 8-bit image as a camera of ``bits`` bits records it (in a 16-bit container)."""
    return np.rint(image8.astype(np.float64) * (2 ** bits - 1) / 255).astype(np.uint16)


@pytest.mark.parametrize("bits", [10, 12, 14, 16])
def test_sixteen_bit_files_are_scaled_by_the_bits_their_data_use(tmp_path, bits):
    path = tmp_path / f"image{bits}.png"
    cv2.imwrite(str(path), at_bits(BGR8, bits))
    image = read_rgb(path)
    assert image.dtype == np.uint8 and image.shape == RGB8.shape
    np.testing.assert_array_equal(image, RGB8)  # before: IMREAD_COLOR kept the top 8 bits, 12-bit data 0-15
    assert cv2.imread(str(path), cv2.IMREAD_COLOR).max() <= 255 >> (16 - bits)


def test_grey_alpha_and_float_images(tmp_path):
    cv2.imwrite(str(tmp_path / "grey.png"), BGR8[..., 0])
    np.testing.assert_array_equal(read_rgb(tmp_path / "grey.png"), np.repeat(BGR8[..., :1], 3, axis=2))
    cv2.imwrite(str(tmp_path / "grey12.tif"), at_bits(BGR8[..., 0], 12))
    np.testing.assert_array_equal(read_rgb(tmp_path / "grey12.tif"), np.repeat(BGR8[..., :1], 3, axis=2))
    cv2.imwrite(str(tmp_path / "alpha.png"), np.dstack([BGR8, np.full(BGR8.shape[:2], 9, np.uint8)]))
    np.testing.assert_array_equal(read_rgb(tmp_path / "alpha.png"), RGB8)
    np.testing.assert_array_equal(to_uint8(np.array([[-0.5, 0.0, 0.5, 1.0, 2.0, np.nan]], np.float32)),
                                  [[0, 0, 128, 255, 255, 0]])
    with pytest.raises(ValueError, match="int32"):
        to_uint8(np.zeros((2, 2), np.int32))


def test_unreadable_files(tmp_path):
    (tmp_path / "junk.png").write_bytes(b"not an image")
    (tmp_path / "empty.png").write_bytes(b"")
    assert read_rgb(tmp_path / "junk.png") is None and read_rgb(tmp_path / "empty.png") is None
    with pytest.raises(OSError):
        read_rgb(tmp_path / "missing.png")


def test_a_scene_image_is_read_at_any_depth_and_checked(tmp_path):
    pytest.importorskip("torch")
    from vfactor.net.pipeline import read_image

    cv2.imwrite(str(tmp_path / "cam0.png"), at_bits(BGR8, 12))
    np.testing.assert_array_equal(read_image(tmp_path / "cam0.png", "frames[0].images.cam0", (52, 36)), RGB8)
    with pytest.raises(SceneError, match="52x36 pixels but the camera's image_size is 640x480"):
        read_image(tmp_path / "cam0.png", "frames[0].images.cam0", (640, 480))
    (tmp_path / "junk.png").write_bytes(b"junk")
    with pytest.raises(SceneError, match="cannot read an image"):
        read_image(tmp_path / "junk.png", "frames[0].images.cam0")


def test_detect_finds_the_same_keypoints_in_a_twelve_bit_file(tmp_path, capsys):
    """`vfactor detect` on a 12-bit PNG: the keypoints of the same picture in 8 bits (before: of a black image)."""
    pytest.importorskip("torch")
    from vfactor.cli import main

    picture = cv2.resize(BGR8, (160, 120), interpolation=cv2.INTER_CUBIC)
    found = {}
    for bits in (8, 12):
        path = tmp_path / f"view{bits}.png"
        cv2.imwrite(str(path), picture if bits == 8 else at_bits(picture, bits))
        out = tmp_path / f"keypoints{bits}.json"
        assert main(["detect", str(path), "--roi", "10", "10", "150", "110", "--out", str(out)]) == 0
        found[bits] = json.loads(out.read_text())["images"][0]["detections"][0]["keypoints"]
    assert found[12] == found[8]
