"""Where the shipped configs and the generated assets are, wherever the package is installed.

``configs/`` sits at the top of the repository and goes into the wheel as the package
``deck_landing_configs`` (``[tool.setuptools.package-dir]`` in pyproject.toml).  As
Gymnasium's ``expand_model_path`` finds model files relative to its package, the config
directory is found relative to a package: ``deck_landing_configs`` through
``importlib.resources`` when it is importable (a wheel, an editable install), else the
source tree's ``configs/`` beside ``landing_env/`` (running from a checkout).

Generated assets (the deck meshes and textures of :mod:`landing_env.scene.deck`) go to the
user cache directory (``platformdirs``), never into the installed package;
``DECK_LANDING_CACHE_DIR`` overrides it.
"""

from __future__ import annotations

import functools
import importlib.util
import os
from pathlib import Path

#: the package name of ``configs/`` in an installed wheel
CONFIG_PACKAGE = "deck_landing_configs"


@functools.cache
def config_dir() -> Path:
    """The directory of the shipped YAML scenarios (with ``calibration/`` and ``train/``)."""
    source = Path(__file__).resolve().parent.parent / "configs"
    # a checkout (or an editable install of one): the files being edited
    if (source / "default.yaml").is_file():
        return source
    spec = importlib.util.find_spec(CONFIG_PACKAGE)
    if spec is not None and spec.submodule_search_locations:
        # a data-only (namespace) package: its directory, as importlib.resources.files gives
        for location in spec.submodule_search_locations:
            if (Path(location) / "default.yaml").is_file():
                return Path(location)
    return source


def cache_dir() -> Path:
    """The user cache directory for generated assets (created on demand)."""
    override = os.environ.get("DECK_LANDING_CACHE_DIR")
    if override:
        return Path(override).expanduser()
    from platformdirs import user_cache_dir

    return Path(user_cache_dir("deck-landing", appauthor=False))


#: the shipped deck-tilt predictors (:mod:`estimation.anticipation.linear_predictors`, fitted by
#: :mod:`agents.training.tilt_predictor_fit` on a scenario family's estimated deck motion)
PREDICTOR_DIR = Path(__file__).resolve().parent / "assets" / "predictors"


def tilt_predictor_path(name: str) -> Path:
    """The file of the deck-tilt predictor ``name``: a shipped one by its family (``bench``:
    ``assets/predictors/deck_tilt_bench.npz``) or a path to a ``.npz``."""
    if name and "/" not in name and "\\" not in name and not name.endswith(".npz"):
        return PREDICTOR_DIR / f"deck_tilt_{name}.npz"
    return Path(name).expanduser()


__all__ = ["CONFIG_PACKAGE", "PREDICTOR_DIR", "cache_dir", "config_dir", "tilt_predictor_path"]
