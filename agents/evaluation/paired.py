"""Two policies on the same seeds: the episodes only one of them lands, and whether the
difference is more than chance.

``evaluate landing`` runs every policy on the same held-out seeds, so two policies' episodes
come in pairs. Their success rates' Wilson intervals treat them as independent samples, and
at 200 episodes they overlap for any difference of a few points. On paired seeds only the
discordant pairs (a seed one policy lands and the other does not) carry the difference:

* the **exact McNemar test** (McNemar 1947, *Psychometrika* 12:153; in its exact form a
  two-sided binomial test of the discordant counts at 1/2, which Fagerland, Lydersen & Laake
  2013, *BMC Medical Research Methodology* 13:91, recommend for small counts): the chance,
  were the two policies equally good, of discordant counts at least this uneven;
* the **difference** in success with the adjusted Wald interval for matched pairs of
  Agresti & Min (2005, *Statistics in Medicine* 24:729, their "Wald+2": half a pair added to
  each of the four cells before the Wald interval, which then covers close to its nominal
  level where the plain Wald interval of a few discordant pairs does not).

::

    python -m agents.evaluation.paired RUN_DIR_OR_JSONL ... --reference quiescent

compares every other policy of the runs with ``quiescent``, scenario by scenario, on the
seeds both ran (:mod:`agents.evaluation.episode_files` reads the runs).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from scipy import stats

from agents.evaluation.episode_files import EpisodeOutcomes, load_outcomes
from landing_env.errors import ConfigError


@dataclass(frozen=True)
class PairedComparison:
    """``policy`` against ``reference`` on the seeds of ``scenario`` both ran."""

    scenario: str
    policy: str
    reference: str
    seeds: int
    both: int
    only_policy: int
    only_reference: int
    neither: int

    @property
    def discordant(self) -> int:
        return self.only_policy + self.only_reference

    @property
    def difference_points(self) -> float:
        """The policy's success less the reference's, percentage points."""
        return 100.0 * (self.only_policy - self.only_reference) / self.seeds

    @property
    def p_value(self) -> float:
        """The exact McNemar test's two-sided p (1 with no discordant seed)."""
        if self.discordant == 0:
            return 1.0
        return float(stats.binomtest(self.only_policy, self.discordant, 0.5).pvalue)

    def interval_points(self, confidence: float = 0.95) -> tuple[float, float]:
        """Agresti and Min's adjusted Wald interval of the difference, percentage points
        (clipped to +-100)."""
        n = self.seeds + 2.0
        difference = (self.only_policy - self.only_reference) / n
        z = float(stats.norm.ppf(0.5 + confidence / 2.0))
        spread = max(self.discordant + 1.0 - (self.only_policy - self.only_reference) ** 2 / n, 0.0)
        half = z * math.sqrt(spread) / n
        return (100.0 * max(difference - half, -1.0), 100.0 * min(difference + half, 1.0))


def pair(policy: EpisodeOutcomes, reference: EpisodeOutcomes) -> PairedComparison:
    """The two runs on the seeds they share (same scenario)."""
    if policy.scenario != reference.scenario:
        raise ConfigError(
            "runs",
            f"{policy.policy} ran {policy.scenario!r}, {reference.policy} "
            f"{reference.scenario!r}: a paired comparison needs one scenario",
        )
    seeds = sorted(set(policy.success_by_seed) & set(reference.success_by_seed))
    if not seeds:
        raise ConfigError(
            "runs",
            f"{policy.policy} ({policy.source}) and {reference.policy} ({reference.source}) "
            f"share no seed on {policy.scenario!r}",
        )
    a = [policy.success_by_seed[s] for s in seeds]
    b = [reference.success_by_seed[s] for s in seeds]
    return PairedComparison(
        scenario=policy.scenario,
        policy=policy.policy,
        reference=reference.policy,
        seeds=len(seeds),
        both=sum(x and y for x, y in zip(a, b, strict=True)),
        only_policy=sum(x and not y for x, y in zip(a, b, strict=True)),
        only_reference=sum(y and not x for x, y in zip(a, b, strict=True)),
        neither=sum(not x and not y for x, y in zip(a, b, strict=True)),
    )


def compare(
    runs: Sequence[EpisodeOutcomes], reference: str, policies: Sequence[str] = ()
) -> list[PairedComparison]:
    """Each policy of ``runs`` (or only ``policies``) against ``reference``, on every scenario
    where both ran, in the order the runs list them."""
    names = list(dict.fromkeys(r.policy for r in runs))
    if reference not in names:
        raise ConfigError("reference", f"{reference!r} is not in the runs; they hold {names}")
    unknown = [p for p in policies if p not in names]
    if unknown:
        raise ConfigError("policy", f"{unknown} are not in the runs; they hold {names}")
    by_key = {(r.scenario, r.policy): r for r in runs}
    comparisons = [
        pair(run, by_key[(run.scenario, reference)])
        for run in runs
        if run.policy != reference
        and (not policies or run.policy in policies)
        and (run.scenario, reference) in by_key
    ]
    if not comparisons:
        raise ConfigError(
            "runs", f"no policy ran a scenario beside {reference!r}: nothing to compare"
        )
    return comparisons


def markdown_table(comparisons: Sequence[PairedComparison]) -> str:
    """One row per comparison."""
    rows = [
        "| scenario | policy | against | seeds | both land | only the policy | only the other "
        "| neither | difference, points (95 % CI) | McNemar p |",
        "|---|---|---|---:|---:|---:|---:|---:|---|---:|",
    ]
    for c in comparisons:
        low, high = c.interval_points()
        rows.append(
            f"| {c.scenario} | {c.policy} | {c.reference} | {c.seeds} | {c.both} | "
            f"{c.only_policy} | {c.only_reference} | {c.neither} | "
            f"{c.difference_points:+.1f} ({low:+.1f} to {high:+.1f}) | {c.p_value:.3g} |"
        )
    return "\n".join(rows)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m agents.evaluation.paired", description=__doc__.split("\n")[0]
    )
    parser.add_argument("runs", nargs="+", type=Path, help="run directories or .jsonl files")
    parser.add_argument("--reference", required=True, help="the policy the others are paired with")
    parser.add_argument("--policy", nargs="*", default=[], help="only these (default: all)")
    args = parser.parse_args(argv)
    try:
        comparisons = compare(load_outcomes(args.runs), args.reference, args.policy)
    except ConfigError as exc:
        parser.error(str(exc))
    print(markdown_table(comparisons))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
