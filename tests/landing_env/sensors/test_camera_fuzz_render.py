"""Fuzz: the planar renderer and the realistic camera never crash, whatever the pose and motion."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from landing_env.config import load_config
from landing_env.sensors.camera_realism import RelativeMotion
from landing_env.world import World

finite = st.floats(-1e3, 1e3, allow_nan=False)


@pytest.fixture(scope="module")
def world() -> Iterator[World]:
    w = World(
        load_config("default", overrides={"camera.mode": "render", "camera.profile": "imx219"})
    )
    yield w
    w.close()


@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    position=st.tuples(st.floats(-5, 5), st.floats(-5, 5), st.floats(-1, 12)),
    rotvec=st.tuples(st.floats(-4, 4), st.floats(-4, 4), st.floats(-4, 4)),
    window=st.tuples(
        st.integers(-50, 600), st.integers(-50, 600), st.integers(1, 300), st.integers(1, 300)
    ),
    velocity=st.tuples(finite, finite, finite),
    spin=st.tuples(st.floats(-50, 50), st.floats(-50, 50), st.floats(-50, 50)),
)
def test_any_pose_window_and_motion_renders_an_image_of_the_window(
    world: World, position, rotvec, window, velocity, spin
) -> None:
    camera = world.camera
    t_wc = np.asarray(position, dtype=float)
    r_wc = Rotation.from_rotvec(rotvec).as_matrix()
    deck = world.deck_state()
    camera.motion = RelativeMotion(
        np.asarray(velocity, float),
        np.asarray(spin, float),
        deck.position_w,
        deck.rotation_wp,
        np.zeros(3),
        np.zeros(3),
    )
    x0, y0, w, h = window
    box = (x0, y0, x0 + w, y0 + h)
    image = camera.render_window(t_wc, r_wc, box, np.random.default_rng(0))
    assert image.shape == (h, w, 3) and image.dtype == np.uint8
    ideal = camera._render_canvas(t_wc, r_wc, box)
    assert ideal.shape == (h, w, 3) and ideal.dtype == np.uint8
