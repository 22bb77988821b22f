"""The per-episode files of ``evaluate landing`` runs, read back seed by seed.

``evaluate landing`` writes one JSON-lines file per policy and scenario
(``landing_<scenario>_<policy>.jsonl``, one episode a line). The figures and comparisons made
across runs (:mod:`agents.evaluation.paired`) read them
here: a directory stands for every ``landing_*.jsonl`` in it; a seed written twice (a resumed
run) counts once, its last line; the same policy and scenario from two files is an error that
names both (pass the files wanted instead of the directory).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from landing_env.errors import ConfigError


@dataclass(frozen=True)
class EpisodeOutcomes:
    """One policy's episodes on one scenario: success by seed, and the file they came from."""

    scenario: str
    policy: str
    source: Path
    success_by_seed: dict[int, bool]

    @property
    def successes(self) -> int:
        return sum(self.success_by_seed.values())

    @property
    def episodes(self) -> int:
        return len(self.success_by_seed)


def jsonl_files(paths: Sequence[Path]) -> list[Path]:
    """The episode files of ``paths`` (run directories or ``.jsonl`` files), in order."""
    files: list[Path] = []
    for path in paths:
        if path.is_dir():
            found = sorted(path.glob("landing_*.jsonl"))
            if not found:
                raise ConfigError("runs", f"{path} holds no landing_*.jsonl file")
            files.extend(found)
        elif path.is_file():
            files.append(path)
        else:
            raise ConfigError("runs", f"{path} is neither a run directory nor a .jsonl file")
    return files


def load_outcomes(paths: Sequence[Path]) -> list[EpisodeOutcomes]:
    """Every (scenario, policy) in the runs' episode files, in the order first met."""
    found: dict[tuple[str, str], EpisodeOutcomes] = {}
    for file in jsonl_files(paths):
        outcomes: dict[tuple[str, str], dict[int, bool]] = {}
        for number, line in enumerate(file.read_text().splitlines(), start=1):
            if not line.strip():
                continue
            try:
                record = json.loads(line)
                key = (str(record["scenario"]), str(record["policy"]))
                if not isinstance(record["success"], bool):
                    raise TypeError(f"success is {record['success']!r}, not true or false")
                outcomes.setdefault(key, {})[int(record["seed"])] = record["success"]
            except (json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
                raise ConfigError(
                    "runs",
                    f"{file}:{number} is not an episode record with scenario, policy, seed and "
                    f"success ({exc})",
                ) from exc
        for key, by_seed in outcomes.items():
            if key in found:
                raise ConfigError(
                    "runs",
                    f"policy {key[1]!r} on {key[0]!r} is in both {found[key].source} and {file}; "
                    "pass only one of them",
                )
            found[key] = EpisodeOutcomes(key[0], key[1], file, by_seed)
    if not found:
        raise ConfigError("runs", "the files hold no episodes")
    return list(found.values())
