"""Project mode's corner noise matches what render-and-detect gives under the realistic camera."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import ks_2samp

from landing_env.config import load_config
from landing_env.sensors.corner_noise import measure_corner_errors, sigma_px
from landing_env.world import World


@pytest.fixture(scope="module")
def samples():
    out = {}
    for mode in ("render", "project"):
        world = World(
            load_config("default", overrides={"sensors": "realistic", "camera.mode": mode})
        )
        try:
            out[mode] = measure_corner_errors(world, 400, np.random.default_rng(7))
        finally:
            world.close()
    return out


def test_project_and_render_corner_errors_have_the_same_spread(samples) -> None:
    rendered, projected = samples["render"], samples["project"]
    assert rendered.missed == 0 and len(rendered.side_px) > 300
    sigma_render = np.sqrt((rendered.errors_px**2).mean())
    sigma_project = np.sqrt((projected.errors_px**2).mean())
    assert sigma_project == pytest.approx(sigma_render, rel=0.2)
    # large tags (near the deck) err most; the model follows them too
    big_r = rendered.side_px > 120
    big_p = projected.side_px > 120
    assert np.sqrt((projected.errors_px[big_p] ** 2).mean()) == pytest.approx(
        np.sqrt((rendered.errors_px[big_r] ** 2).mean()), rel=0.2
    )


def test_project_and_render_corner_errors_have_the_same_distribution(samples) -> None:
    rendered, projected = samples["render"], samples["project"]
    result = ks_2samp(rendered.errors_px.reshape(-1), projected.errors_px.reshape(-1))
    # thousands of samples: bound the largest CDF gap rather than the p-value
    assert result.statistic < 0.05


def test_ideal_sensors_keep_project_mode_noise_free() -> None:
    config = load_config("default")
    assert config.camera.pixel_noise_model == "constant" and config.camera.pixel_noise_px == 0.0
    assert sigma_px((0.0, 0.15, 0.0, 6.19e-6), np.array([100.0]), np.array([0.0]))[0] > 0.0
