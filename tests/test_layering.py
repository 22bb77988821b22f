"""`estimation/` must run on a real drone: it imports neither pybullet nor gymnasium."""

from __future__ import annotations

import pkgutil
import subprocess
import sys

import estimation


def test_estimation_imports_no_simulator_or_rl_package() -> None:
    modules = [f"estimation.{m.name}" for m in pkgutil.iter_modules(estimation.__path__)]
    code = (
        "import importlib, sys\n"
        f"for name in {modules!r}: importlib.import_module(name)\n"
        "bad = sorted(m for m in sys.modules if m.split('.')[0] in "
        "('pybullet', 'pybullet_utils', 'gymnasium', 'landing_env', 'stable_baselines3'))\n"
        "print(','.join(bad))\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    )
    assert len(modules) > 5
    assert result.stdout.strip() == "", result.stdout
