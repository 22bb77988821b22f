"""The package as a user installs it: a wheel with the configs as package data, run from
another directory, writing generated assets to the user cache."""

from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest
import tomllib

from tests.paths import ROOT


def test_every_sub_package_is_listed_in_pyproject() -> None:
    from setuptools import find_packages

    listed = set(
        tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"]
    )
    found = set(find_packages(str(ROOT), include=["landing_env*", "estimation*", "agents*"]))
    assert found <= listed, f"add {sorted(found - listed)} to [tool.setuptools] packages"


def test_the_config_directory_is_found_relative_to_the_package() -> None:
    from landing_env.config import available_configs
    from landing_env.resources import config_dir

    assert (config_dir() / "default.yaml").is_file()
    assert {"default", "bench-ss4", "paper-stewart"} <= set(available_configs())


def test_generated_deck_assets_go_to_the_user_cache(tmp_path: Path) -> None:
    code = (
        "from landing_env.scene.deck import GENERATED_DIR, deck_asset_files;"
        "from landing_env.scene.deck import DeckSurfaceConfig;"
        "import landing_env;"
        "obj, png = deck_asset_files(DeckSurfaceConfig());"
        "print(obj.parent)"
    )
    env = {**os.environ, "DECK_LANDING_CACHE_DIR": str(tmp_path / "cache")}
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True, check=True
    ).stdout.strip()
    assert Path(out).is_relative_to(tmp_path / "cache")
    assert list(Path(out).glob("deck_*.obj"))


SMOKE = """
import sys, warnings
import gymnasium as gym
import landing_env
from landing_env.scenarios import SCENARIO_IDS
assert "site-packages" in landing_env.__file__, landing_env.__file__
for env_id in [*SCENARIO_IDS, "DeckLanding-v2", "DeckLandingTiming-v0"]:
    kwargs = {} if env_id in SCENARIO_IDS else {"config": "bench-ss4",
              "overrides": {"simulation.drone_fixed": False, "camera.mode": "project"}}
    env = gym.make(env_id, **kwargs)
    observation, _ = env.reset(seed=0)
    assert env.observation_space.contains(observation), env_id
    env.close()
print("made", len(SCENARIO_IDS) + 2)
"""


@pytest.mark.slow
def test_the_wheel_installs_and_runs_from_another_directory(tmp_path: Path) -> None:
    dist = tmp_path / "dist"
    subprocess.run(
        [sys.executable, "-m", "build", "--wheel", "--no-isolation", "--outdir", str(dist)],
        cwd=ROOT, check=True, capture_output=True,
    )  # fmt: skip
    wheel = next(dist.glob("deck_landing-*.whl"))
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    python = venv / "bin" / "python"
    # the fresh venv sees the shared dependencies through a .pth, but not the checkout or its
    # editable install (.pth files inside an added directory are not processed)
    site = subprocess.run(
        [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        check=True, capture_output=True, text=True,
    ).stdout.strip()  # fmt: skip
    Path(site, "shared_deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    subprocess.run(
        [sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps",
         "--no-index", "--quiet", str(wheel)],
        check=True, capture_output=True,
    )  # fmt: skip
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    env = {**os.environ, "DECK_LANDING_CACHE_DIR": str(tmp_path / "cache")}
    env.pop("PYTHONPATH", None)
    made = subprocess.run(
        [str(python), "-c", SMOKE], cwd=elsewhere, env=env, capture_output=True, text=True
    )
    assert made.returncode == 0, made.stderr[-3000:]
    assert "made" in made.stdout
    assert not list(Path(site).glob("landing_env/assets/generated*"))  # nothing written there
    assert list((tmp_path / "cache").glob("*/deck_*.obj"))
    cli = subprocess.run(
        [str(venv / "bin" / "deck-landing"), "evaluate", "landing", "--policy", "land-now",
         "--scenario", "bench-ss4", "--episodes", "2", "--workers", "1", "--no-progress",
         "--out", str(tmp_path / "out")],
        cwd=elsewhere, env=env, capture_output=True, text=True,
    )  # fmt: skip
    assert cli.returncode == 0, cli.stderr[-3000:]
    assert (tmp_path / "out" / "landing_bench-ss4.md").is_file()


def test_the_version_is_one_across_pyproject_citation_changelog_and_docs() -> None:
    import re

    version = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
    citation = re.search(r"^version: (\S+)$", (ROOT / "CITATION.cff").read_text(), re.M)
    assert citation and citation.group(1) == version
    released = re.search(
        r"^## \[(\d[^\]]*)\] - (\d{4}-\d\d-\d\d)$", (ROOT / "CHANGELOG.md").read_text(), re.M
    )
    assert released and released.group(1) == version
    conf = (ROOT / "docs" / "conf.py").read_text()
    assert "release = installed_version(project)" in conf  # the installed package's
