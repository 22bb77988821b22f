"""AprilTag detection (estimation.detection): the project's pixel convention, the images it
takes, the detections it drops, and its native detector's settings and lifetime."""

from __future__ import annotations

import copy
import pickle

import cv2
import numpy as np
import pytest

from estimation.detection import AprilTagDetector, min_detect_side_px, to_gray
from estimation.frames import TAG_CORNER_SIGNS
from landing_env.scene.deck import opencv_tag_bits

CELL_PX = 10
#: the tag's black border starts at this pixel column and row
ORIGIN_PX = (40, 60)


def _tag_image(bits: np.ndarray, origin_px: tuple[int, int] = ORIGIN_PX, shape=(200, 240)):
    """A grey image (white) holding the 8x8 cells ``bits`` (1 = white), CELL_PX pixels each."""
    image = np.full(shape, 255, dtype=np.uint8)
    cells = np.kron(bits, np.ones((CELL_PX, CELL_PX)))
    x, y = origin_px
    image[y : y + cells.shape[0], x : x + cells.shape[1]] = np.where(cells > 0.5, 255, 0)
    return image


def _expected_corners(origin_px: tuple[int, int] = ORIGIN_PX) -> np.ndarray:
    """The black border's outer corners: pixel edges, half a pixel before the first pixel's
    centre and after the last's (OpenCV's convention), in the order of TAG_CORNER_SIGNS."""
    x, y = origin_px
    half = 4 * CELL_PX
    centre = np.array([x + half - 0.5, y + half - 0.5])
    return centre + half * TAG_CORNER_SIGNS


@pytest.fixture
def detector():
    detector = AprilTagDetector()
    yield detector
    detector.close()


def test_a_tag_is_detected_with_its_corners_on_the_edges_of_its_black_border(detector) -> None:
    grey = _tag_image(opencv_tag_bits(17))
    rgb = np.repeat(grey[..., None], 3, axis=2)
    rgba = np.concatenate([rgb, np.full((*grey.shape, 1), 255, dtype=np.uint8)], axis=2)
    for image in (grey, rgb, rgba):
        (detection,) = detector.detect(image)
        assert detection.tag_id == 17 and type(detection.tag_id) is int
        assert detection.hamming == 0 and type(detection.hamming) is int
        assert type(detection.decision_margin) is float and detection.decision_margin > 10.0
        assert detection.corners_px.dtype == float
        # within 0.3 px of the edges (measured 0.21 px at most on this sharp image); without
        # the shift to OpenCV's convention they are 0.5 px off, with it the wrong way 1 px
        np.testing.assert_allclose(detection.corners_px, _expected_corners(), atol=0.3)


def test_to_gray_weighs_the_red_green_and_blue_of_rgb_and_rgba_and_keeps_grey() -> None:
    red, green, blue = (np.zeros((2, 3, 3), dtype=np.uint8) for _ in range(3))
    red[..., 0], green[..., 1], blue[..., 2] = 255, 255, 255
    # ITU-R BT.601 weights: 0.299, 0.587, 0.114
    assert [int(to_gray(c)[0, 0]) for c in (red, green, blue)] == [76, 150, 29]
    rgba = np.concatenate([red, np.zeros((2, 3, 1), dtype=np.uint8)], axis=2)
    assert to_gray(rgba).shape == (2, 3) and int(to_gray(rgba)[1, 2]) == 76
    grey = np.arange(24, dtype=np.uint8).reshape(4, 6)[:, ::2]  # a strided view
    out = to_gray(grey)
    np.testing.assert_array_equal(out, grey)
    assert out.flags.c_contiguous


def test_an_image_of_another_type_or_shape_is_refused_saying_what_it_is() -> None:
    with pytest.raises(TypeError) as error:
        to_gray(np.zeros((4, 4), dtype=np.float64))
    assert str(error.value) == "expected a uint8 image, got float64"
    for shape in ((4, 4, 2), (4,), (2, 4, 4, 3)):
        with pytest.raises(ValueError) as value_error:
            to_gray(np.zeros(shape, dtype=np.uint8))
        assert str(value_error.value) == (
            f"expected an HxW, HxWx3 or HxWx4 image, got shape {shape}"
        )


def test_detect_refuses_other_than_uint8_and_passes_over_images_too_thin_for_a_tag(
    detector,
) -> None:
    with pytest.raises(TypeError) as error:
        detector.detect(np.zeros((40, 40), dtype=np.int16))
    assert str(error.value) == "expected a uint8 image, got int16"
    # thinner than 10 px in either direction (the native detector crashes on such shapes)
    for shape in ((3, 200), (200, 3), (9, 200, 3), (200, 2, 4)):
        assert detector.detect(np.full(shape, 255, dtype=np.uint8)) == ()
    with pytest.raises(ValueError, match="HxWx3"):
        detector.detect(np.zeros((2, 20, 20, 3), dtype=np.uint8))


def test_an_image_thinner_than_the_smallest_side_never_reaches_the_native_detector(
    detector, monkeypatch: pytest.MonkeyPatch
) -> None:
    reached: list[tuple[int, ...]] = []

    def native(gray: np.ndarray) -> list:
        reached.append(gray.shape)
        return []

    monkeypatch.setattr(detector._detector, "detect", native)
    side = detector.min_side_px
    for shape in ((side - 1, 200), (200, side - 1), (side - 1, 200, 3), (200, side - 1, 4)):
        assert detector.detect(np.full(shape, 255, dtype=np.uint8)) == ()
    assert reached == []
    # from the smallest side on, grey or colour, the image is the native detector's
    for shape in ((side, 200), (200, side, 3)):
        detector.detect(np.full(shape, 255, dtype=np.uint8))
    assert reached == [(side, 200), (200, side)]


def test_a_detector_of_another_family_finds_that_familys_tags_alone() -> None:
    aruco = cv2.aruco
    marker = aruco.generateImageMarker(
        aruco.getPredefinedDictionary(aruco.DICT_APRILTAG_25h9), 3, 9 * 16
    )
    image = np.full((300, 300), 255, dtype=np.uint8)
    image[78:222, 78:222] = marker  # 9 modules of 16 px: the black border and the 5x5 bits
    tag25, tag36 = AprilTagDetector(families="tag25h9"), AprilTagDetector()
    try:
        assert [d.tag_id for d in tag25.detect(image)] == [3]
        assert tag36.detect(image) == ()
    finally:
        tag25.close()
        tag36.close()


def test_a_tag_decoded_with_a_bit_wrong_is_kept_only_when_that_many_are_allowed() -> None:
    bits = opencv_tag_bits(5)
    bits[3, 3] = 1.0 - bits[3, 3]
    wrong = _tag_image(bits)
    strict, lenient = AprilTagDetector(), AprilTagDetector(max_hamming=1)
    try:
        assert strict.detect(wrong) == ()
        (detection,) = lenient.detect(wrong)
        assert (detection.tag_id, detection.hamming) == (5, 1)
        # a wrongly decoded tag does not hide a good one
        both = np.minimum(wrong, _tag_image(opencv_tag_bits(9), (140, 60)))
        assert [d.tag_id for d in strict.detect(both)] == [9]
        both = np.minimum(_tag_image(opencv_tag_bits(9)), _tag_image(bits, (140, 60)))
        assert [d.tag_id for d in strict.detect(both)] == [9]
    finally:
        strict.close()
        lenient.close()


def test_the_settings_reach_the_native_detector_and_a_pickle_rebuilds_them() -> None:
    default = AprilTagDetector()
    assert default.__reduce__() == (AprilTagDetector, ("tag36h11", 1.0, 0.0, True, 0.25, 1, 0))
    assert default.families == "tag36h11" and default.max_hamming == 0
    assert default.min_side_px == min_detect_side_px(1.0) == 10
    given = AprilTagDetector("tag36h11", 3.0, 0.8, False, 0.5, 2, 1)
    assert given.min_side_px == 12 and given.max_hamming == 1
    # the wrapped pupil-apriltags detector keeps what it was built with
    assert given._detector.params == {
        "families": ["tag36h11"],
        "nthreads": 2,
        "quad_decimate": 3.0,
        "quad_sigma": 0.8,
        "refine_edges": 0,
        "decode_sharpening": 0.5,
        "debug": 0,
    }
    copied = pickle.loads(pickle.dumps(given))
    assert copied is not given and copied.__reduce__() == given.__reduce__()
    assert copied._detector.params == given._detector.params
    for detector in (default, given, copied):
        detector.close()


@pytest.mark.parametrize(("argument", "value"), [("quad_decimate", 0.9), ("nthreads", 0)])
def test_a_detector_refuses_a_setting_below_one_naming_it(argument: str, value: float) -> None:
    with pytest.raises(ValueError) as error:
        AprilTagDetector(**{argument: value})
    assert str(error.value) == f"{argument} must be >= 1, got {value}"


def test_a_detector_is_shared_by_deep_copies_and_freed_when_closed(detector) -> None:
    holder = {"a": detector, "b": [detector]}
    copied = copy.deepcopy(holder)
    assert copied["a"] is detector and copied["b"][0] is detector
    native = detector._detector
    assert native.tag_detector_ptr is not None
    detector.close()
    # freed: the pointer cleared, so that pupil-apriltags' own destructor does nothing
    assert native.tag_detector_ptr is None
    with pytest.raises(RuntimeError) as error:
        detector.detect(_tag_image(opencv_tag_bits(17)))
    assert str(error.value) == "the detector has been closed"
