"""The helideck forecast fitted once per machine: a cached forecast is the fresh fit to the bit,
any input the fit reads names another entry, a damaged entry is fitted again, and the
scenario's forecast (``deck_forecast_for``) is read from the cache by a new process."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from estimation.anticipation.linear_predictors import LinearMotionPredictor
from landing_env.anticipation import hms_forecast
from landing_env.anticipation.hms_forecast import (
    FIT_SEED,
    cached_deck_forecast,
    deck_forecast_for,
    forecast_cache_path,
)
from landing_env.config import load_config
from landing_env.scenarios import SCENARIOS
from landing_env.sea.hms import HelideckMonitorConfig

#: the sizes of the ``small_forecast`` fixture's fit (tests/conftest.py)
SMALL = {"realizations": 3, "record_s": 400.0}


@pytest.fixture
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """An empty cache directory of this test's own."""
    monkeypatch.setenv("DECK_LANDING_CACHE_DIR", str(tmp_path))
    return tmp_path


def ss4_motion():
    return load_config(SCENARIOS["ship-ss4"].config).motion


def spy_fit(monkeypatch: pytest.MonkeyPatch, forecast: LinearMotionPredictor) -> list[dict]:
    """Replace the fit by one that records its arguments and returns ``forecast``."""
    calls: list[dict] = []

    def fit(**arguments):
        calls.append(arguments)
        return forecast

    monkeypatch.setattr(hms_forecast, "fit_deck_forecast", fit)
    return calls


def assert_identical(a: LinearMotionPredictor, b: LinearMotionPredictor) -> None:
    """Every field equal, arrays to the bit and of the same dtype."""
    for item in dataclasses.fields(LinearMotionPredictor):
        x, y = getattr(a, item.name), getattr(b, item.name)
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and x.shape == y.shape, item.name
            assert np.array_equal(x, y), item.name
        else:
            assert type(x) is type(y) and x == y, item.name


def test_a_cached_forecast_is_the_fresh_fit_to_the_bit(cache: Path, small_forecast) -> None:
    motion = ss4_motion()
    path = forecast_cache_path(motion, **SMALL)
    assert path.parent.parent == cache and not path.exists()
    written = cached_deck_forecast(motion, **SMALL)
    assert path.is_file()
    assert_identical(written, small_forecast)
    # read back: the file's forecast, not a refit, equal to the fresh fit in every bit
    read = cached_deck_forecast(motion, **SMALL)
    assert read is not written
    assert_identical(read, small_forecast)
    window = np.sin(np.arange(read.n_window * 5, dtype=float)).reshape(-1, 5) * 0.1
    valid = np.ones(read.n_window, dtype=bool)
    assert np.array_equal(
        read.predict_targets(window, valid), small_forecast.predict_targets(window, valid)
    )


def test_every_input_of_the_fit_names_another_cache_entry(
    cache: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    motion = ss4_motion()
    base = forecast_cache_path(motion, **SMALL)
    assert forecast_cache_path(motion, HelideckMonitorConfig(), seed=FIT_SEED, **SMALL) == base
    other_sea = load_config(SCENARIOS["ship-ss5"].config).motion
    changed = [
        forecast_cache_path(other_sea, **SMALL),
        forecast_cache_path([motion, other_sea], **SMALL),
        forecast_cache_path(motion, HelideckMonitorConfig(rate_hz=20.0), **SMALL),
        forecast_cache_path(motion, realizations=4, record_s=400.0),
        forecast_cache_path(motion, realizations=3, record_s=401.0),
        forecast_cache_path(motion, seed=FIT_SEED + 1, **SMALL),
    ]
    with monkeypatch.context() as patch:
        patch.setattr(hms_forecast, "BLOCK", hms_forecast.BLOCK + 1)
        changed.append(forecast_cache_path(motion, **SMALL))
    with monkeypatch.context() as patch:
        patch.setattr(hms_forecast, "_code_digest", lambda: "an edited fit")
        changed.append(forecast_cache_path(motion, **SMALL))
    assert len({base, *changed}) == len(changed) + 1


def test_the_code_digest_reads_every_file_of_the_fits_code(monkeypatch: pytest.MonkeyPatch) -> None:
    digest = hms_forecast._code_digest.__wrapped__
    full = digest()
    assert full == hms_forecast._code_digest()
    monkeypatch.setattr(hms_forecast, "FIT_CODE", hms_forecast.FIT_CODE[:-1])
    assert digest() != full  # the waves package's files count


def test_the_same_inputs_are_read_back_and_a_changed_one_is_fitted(
    cache: Path, small_forecast, monkeypatch: pytest.MonkeyPatch
) -> None:
    motion = ss4_motion()
    calls = spy_fit(monkeypatch, small_forecast)
    cached_deck_forecast(motion, **SMALL)
    cached_deck_forecast(motion, seed=FIT_SEED, **SMALL)
    assert len(calls) == 1
    cached_deck_forecast(motion, seed=FIT_SEED + 1, **SMALL)
    assert [call["seed"] for call in calls] == [FIT_SEED, FIT_SEED + 1]
    assert len(list((cache / hms_forecast.CACHE_FOLDER).glob("*.npz"))) == 2


def test_a_damaged_cache_entry_is_fitted_again_and_replaced(
    cache: Path, small_forecast, monkeypatch: pytest.MonkeyPatch
) -> None:
    motion = ss4_motion()
    path = forecast_cache_path(motion, **SMALL)
    path.parent.mkdir(parents=True)
    path.write_bytes(b"not a forecast")
    calls = spy_fit(monkeypatch, small_forecast)
    assert_identical(cached_deck_forecast(motion, **SMALL), small_forecast)
    assert len(calls) == 1
    assert_identical(LinearMotionPredictor.load(path), small_forecast)


def test_a_scenarios_forecast_is_read_from_the_cache_by_a_new_process(
    cache: Path, small_forecast, monkeypatch: pytest.MonkeyPatch
) -> None:
    config = load_config(SCENARIOS["ship-ss4"].config)
    hms = HelideckMonitorConfig()
    calls = spy_fit(monkeypatch, small_forecast)
    monkeypatch.setattr(hms_forecast, "_FITTED", {})
    first = deck_forecast_for(config, hms)
    sizes = {"realizations": hms_forecast.REALIZATIONS, "record_s": hms_forecast.RECORD_S}
    assert calls == [{"motion": (config.motion,), "hms": hms, **sizes, "seed": FIT_SEED}]
    assert forecast_cache_path((config.motion,), hms).is_file()
    monkeypatch.setattr(hms_forecast, "_FITTED", {})  # as a new process starts
    assert_identical(deck_forecast_for(config, hms), first)
    assert len(calls) == 1


def test_one_sea_given_alone_or_in_a_list_names_one_entry_of_one_numpy_and_one_machine(
    cache: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    motion = ss4_motion()
    base = forecast_cache_path(motion, **SMALL)
    assert forecast_cache_path([motion], **SMALL) == base == forecast_cache_path((motion,), **SMALL)
    with monkeypatch.context() as patch:
        patch.setattr(hms_forecast.np, "__version__", "0.0.0")
        other_numpy = forecast_cache_path(motion, **SMALL)
    with monkeypatch.context() as patch:
        patch.setattr(hms_forecast.platform, "machine", lambda: "another architecture")
        other_machine = forecast_cache_path(motion, **SMALL)
    assert len({base, other_numpy, other_machine}) == 3
