"""One picture, however a recording holds it, reads back as one image: every raw encoding of
``sensor_msgs/Image`` (rows padded or not), PNG in ``sensor_msgs/CompressedImage``, and the
plain folder's image files, grey or colour with or without alpha."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

pytest.importorskip("rosbags")
from agents.io import messages as m
from agents.io.bag import CHANNELS, IMAGE_ENCODINGS, decode_image, read_bag
from agents.io.recording import Topics, read_folder

HEIGHT, WIDTH = 5, 7
#: every channel different from the others, so that a swapped channel shows
PICTURE = np.random.default_rng(11).integers(0, 256, (HEIGHT, WIDTH, 3), dtype=np.uint8)
GREY = PICTURE[:, :, 1].copy()
ALPHA = np.full((HEIGHT, WIDTH, 1), 77, np.uint8)
PAD_BYTE = 0xAB


def wire_pixels(rgb: np.ndarray, encoding: str) -> np.ndarray:
    """The picture's bytes in ``encoding``'s channel order, (height, width, channels)."""
    grey = rgb[:, :, 1]
    alpha = np.full((*rgb.shape[:2], 1), ALPHA[0, 0, 0], np.uint8)
    return {
        "mono8": grey[:, :, None],
        "8UC1": grey[:, :, None],
        "rgb8": rgb,
        "bgr8": rgb[:, :, ::-1],
        "rgba8": np.concatenate([rgb, alpha], axis=2),
        "bgra8": np.concatenate([rgb[:, :, ::-1], alpha], axis=2),
    }[encoding]


def raw_image(t_s: float, rgb: np.ndarray, encoding: str, pad: int) -> object:
    """A ``sensor_msgs/Image`` of the picture in ``encoding``, each row padded by ``pad``
    bytes (``step`` longer than a row's pixels, as some drivers align rows)."""
    pixels = wire_pixels(rgb, encoding)
    height, width, channels = pixels.shape
    rows = pixels.reshape(height, width * channels)
    rows = np.concatenate([rows, np.full((height, pad), PAD_BYTE, np.uint8)], axis=1)
    return m.msg(
        m.IMAGE,
        header=m.header(t_s, "camera"),
        height=height,
        width=width,
        encoding=encoding,
        is_bigendian=0,
        step=width * channels + pad,
        data=np.ascontiguousarray(rows).reshape(-1),
    )


def png_image(t_s: float, pixels_bgr: np.ndarray) -> object:
    ok, data = cv2.imencode(".png", pixels_bgr)
    assert ok
    return m.msg(m.COMPRESSED, header=m.header(t_s, "camera"), format="png", data=data.reshape(-1))


def expected(encoding: str, rgb: np.ndarray = PICTURE) -> np.ndarray:
    return rgb[:, :, 1] if CHANNELS.get(encoding, 3) == 1 else rgb


def test_the_same_picture_in_every_encoding_reads_back_as_one_image(tmp_path: Path) -> None:
    path = tmp_path / "encodings.mcap"
    written: list[tuple[str, np.ndarray]] = []
    with path.open("wb") as stream:
        writer = m.McapWriter(stream)
        t_s = 0.0
        for encoding in IMAGE_ENCODINGS:
            for pad in (0, 3):
                t_s += 0.1
                writer.write(
                    "/camera/image_raw", m.IMAGE, raw_image(t_s, PICTURE, encoding, pad), t_s
                )
                written.append((f"{encoding} step +{pad}", expected(encoding)))
        compressed = {
            "png rgb": (PICTURE[:, :, ::-1], PICTURE),
            "png rgba": (np.concatenate([PICTURE[:, :, ::-1], ALPHA], axis=2), PICTURE),
            "png grey": (GREY, GREY),
        }
        for name, (pixels_bgr, picture) in compressed.items():
            t_s += 0.1
            writer.write("/camera/compressed", m.COMPRESSED, png_image(t_s, pixels_bgr), t_s)
            written.append((name, picture))
        writer.finish()
    raw = read_bag(path)
    assert not raw.skipped
    assert len(raw.frames) == 2 * len(IMAGE_ENCODINGS)
    png = read_bag(path, Topics(image="/camera/compressed"))
    assert not png.skipped and len(png.frames) == len(compressed)
    for (name, picture), frame in zip(written, raw.frames + png.frames, strict=True):
        assert frame.image is not None and frame.image.dtype == np.uint8, name
        np.testing.assert_array_equal(frame.image, picture, err_msg=name)


@pytest.mark.parametrize(
    ("name", "pixels_bgr", "picture"),
    [
        ("grey.png", GREY, GREY),
        ("colour.png", PICTURE[:, :, ::-1], PICTURE),
        ("alpha.png", np.concatenate([PICTURE[:, :, ::-1], ALPHA], axis=2), PICTURE),
    ],
)
def test_a_folders_image_file_reads_as_grey_or_rgb(
    tmp_path: Path, name: str, pixels_bgr: np.ndarray, picture: np.ndarray
) -> None:
    assert cv2.imwrite(str(tmp_path / name), pixels_bgr)  # OpenCV writes its own BGR order
    (tmp_path / "frames.csv").write_text(f"t_s,image\n0.5,{name}\n")
    (frame,) = read_folder(tmp_path).frames
    np.testing.assert_array_equal(frame.image, picture)


@settings(max_examples=150, deadline=None)
@given(
    encoding=st.sampled_from(IMAGE_ENCODINGS),
    height=st.integers(1, 6),
    width=st.integers(1, 6),
    pad=st.integers(0, 9),
    seed=st.integers(0, 2**32 - 1),
)
def test_any_raw_image_decodes_to_its_picture(
    encoding: str, height: int, width: int, pad: int, seed: int
) -> None:
    rgb = np.random.default_rng(seed).integers(0, 256, (height, width, 3), dtype=np.uint8)
    message = raw_image(0.0, rgb, encoding, pad)
    image = decode_image(message, m.IMAGE, "/camera/image_raw")
    assert image.flags["C_CONTIGUOUS"]
    np.testing.assert_array_equal(image, expected(encoding, rgb))


def raw_header(encoding: str, height: int, width: int, step: int, size: int) -> object:
    return m.msg(
        m.IMAGE, header=m.header(0.0, "camera"), height=height, width=width,
        encoding=encoding, is_bigendian=0, step=step, data=np.zeros(size, np.uint8),
    )  # fmt: skip


@pytest.mark.parametrize(
    ("encoding", "height", "width", "step", "size"),
    [
        ("rgb8", 2, 2, 5, 10),  # a row shorter than its pixels (and than its pixels / 3 not)
        ("rgb8", 2, 2, 6, 11),  # fewer bytes than its rows
        ("rgb8", 0, 2, 6, 12),  # no row
        ("mono8", 2, 0, 2, 4),  # no column
    ],
)
def test_a_raw_image_whose_size_and_data_disagree_is_refused_naming_its_bytes_and_rows(
    encoding: str, height: int, width: int, step: int, size: int
) -> None:
    message = raw_header(encoding, height, width, step, size)
    expected_text = f"/cam: data holds {size} bytes, not {height} rows of {step}"
    with pytest.raises(ValueError, match=f"^{expected_text}$"):
        decode_image(message, m.IMAGE, "/cam")


def test_an_unknown_encoding_or_an_undecodable_compressed_image_is_refused_by_name() -> None:
    known = "mono8, 8UC1, rgb8, bgr8, rgba8, bgra8"
    with pytest.raises(ValueError, match=f"^/cam: encoding 'yuv422' unknown; known: {known}$"):
        decode_image(raw_header("yuv422", 2, 2, 4, 8), m.IMAGE, "/cam")
    for data in (b"", b"not a png"):
        message = m.msg(
            m.COMPRESSED, header=m.header(0.0, "camera"), format="png",
            data=np.frombuffer(data, np.uint8),
        )  # fmt: skip
        with pytest.raises(ValueError, match=r"^/cam: format 'png' data cannot be decoded$"):
            decode_image(message, m.COMPRESSED, "/cam")
