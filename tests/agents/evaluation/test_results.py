"""The committed result summaries (configs/results/*.json): each reads, its percentages are its
counts, its command reproduces its seeds, and every recommendation and every scenario's
default policy has its figure there."""

from __future__ import annotations

import copy
import json

import pytest

from agents.cli import build_parser
from agents.evaluation import results
from agents.evaluation.results import (
    default_figures,
    parse_summary,
    recommended_figures,
    summaries,
    summary_dir,
    summary_from_run,
)
from agents.policies.registry import DEFAULT_POLICY, RECOMMENDED
from landing_env.errors import ConfigError

SUMMARY = {
    "title": "t",
    "date": "2026-11-29",
    "commit": "abc1234",
    "command": "deck-landing evaluate landing --scenario bench-ss5 --sensors realistic "
    "--episodes 200 --seed 5000000",
    "scenario": "bench-ss5",
    "sensing": "realistic",
    "episodes": 200,
    "first_seed": 5_000_000,
    "rows": [
        {
            "policy": "predictive",
            "successes": 165,
            "episodes": 200,
            "success_pct": 82.5,
            "ci95_low_pct": 76.6,
            "ci95_high_pct": 87.1,
        }
    ],
}


def test_a_well_formed_summary_reads_with_its_wilson_interval() -> None:
    result = parse_summary("x", SUMMARY)
    assert result.row("predictive").cell() == "82.5 % (76.6-87.1)"
    assert result.seeds == "200 seeds from 5 000 000"


@pytest.mark.parametrize(
    ("change", "named"),
    [
        (lambda d: d.pop("commit"), "'commit' is missing"),
        (lambda d: d.update(date="29/11/2026"), "'date'"),
        (lambda d: d.update(episodes="200"), "'episodes'"),
        (lambda d: d.update(seeds=3), "unknown fields \\['seeds'\\]"),
        (lambda d: d["rows"][0].update(success_pct=85.0), "success_pct = 85.0 but"),
        (lambda d: d["rows"][0].update(ci95_low_pct=70.0), "ci95_low_pct = 70.0 but"),
        (lambda d: d["rows"][0].update(successes=201), "successes must lie"),
        (lambda d: d.update(rows=[]), "'rows' is empty"),
    ],
)
def test_a_broken_summary_is_refused_naming_the_file_and_field(change, named: str) -> None:
    data = copy.deepcopy(SUMMARY)
    change(data)
    with pytest.raises(ConfigError, match=named) as error:
        parse_summary("broken", data)
    assert "configs/results/broken.json" in str(error.value)


def test_every_committed_summary_reads() -> None:
    names = [path.stem for path in summary_dir().glob("*.json")]
    assert sorted(names) == list(summaries()) and len(names) >= 10


@pytest.mark.parametrize("name", sorted(p.stem for p in summary_dir().glob("*.json")))
def test_a_summarys_command_flies_its_scenario_seeds_and_sensing(name: str) -> None:
    result = summaries()[name]
    words = result.command.split()
    assert words[:3] == ["deck-landing", "evaluate", "landing"], result.command
    args = build_parser().parse_args(words[1:])
    assert result.scenario in args.scenario
    assert args.seed == result.first_seed and args.episodes == result.episodes
    assert args.sensors == result.sensing
    if args.policy:  # without --policy it flies the scenario's default
        assert {row.policy for row in result.rows} <= {*args.policy, "oracle", "deck-oracle"}
    else:
        assert result.rows[0].policy == DEFAULT_POLICY[result.scenario]


def test_every_recommendation_has_its_figure_in_a_summary_of_its_setting() -> None:
    figures = recommended_figures()
    assert [f.policy for f in figures] == [rec.policy for rec in RECOMMENDED]
    for figure, rec in zip(figures, RECOMMENDED, strict=True):
        assert (figure.result.scenario, figure.result.sensing) == (rec.scenario, rec.sensing)
        assert figure.result.chosen_by, f"{rec.summary} does not say what chose {rec.policy}"
        assert figure.row.episodes >= 100


def test_every_scenario_with_a_default_policy_has_its_figure() -> None:
    figures = {figure.label: figure for figure in default_figures()}
    assert set(figures) == set(DEFAULT_POLICY)
    for scenario, figure in figures.items():
        assert figure.result.scenario == scenario
        assert figure.row.policy == DEFAULT_POLICY[scenario]


def test_a_recommendation_whose_summary_measured_another_setting_is_refused(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from agents.policies.registry import Recommendation

    wrong = Recommendation("x", "ship-ss5", "ideal", "quiescent", "ship-ss5-realistic-heldout")
    monkeypatch.setattr(results, "RECOMMENDED", (wrong,))
    with pytest.raises(ConfigError, match="not ship-ss5 with ideal"):
        recommended_figures()


def test_a_summary_written_from_an_evaluation_keeps_its_counts_seeds_and_command() -> None:
    run = {
        "scenario": "bench-ss5",
        "estimator": None,
        "first_seed": 5_000_000,
        "command": "deck-landing evaluate landing --scenario bench-ss5 --sensors realistic "
        "--episodes 200 --seed 5000000 --workers 1 --no-progress --resume",
        "summaries": [
            {"policy": "predictive", "successes": 165, "episodes": 200},
            {"policy": "land-now", "successes": 100, "episodes": 200},
        ],
    }
    data = summary_from_run(
        run, "t", "abc1234", "2026-11-29", "realistic", policies=("predictive",)
    )
    assert data["rows"] == SUMMARY["rows"]
    assert data["command"].endswith("--seed 5000000 --workers 1")
    assert data["estimator"] == "tight" and data["first_seed"] == 5_000_000
    assert parse_summary("new", json.loads(json.dumps(data))).row("predictive").successes == 165


def test_a_default_figure_is_the_one_on_the_latest_seeds_and_a_tie_there_is_refused(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    figures = {figure.label: figure for figure in default_figures()}
    # paper-stewart has its selection (from 1 000 000) and its held-out (5 000 000) summaries
    assert figures["paper-stewart"].result.first_seed == 5_000_000
    table = dict(summaries())
    twin = parse_summary(
        "twin",
        {**SUMMARY, "scenario": "paper-stewart"}
        | {"rows": [{**SUMMARY["rows"][0], "policy": "quiescent"}]},
    )
    table["twin"] = twin
    monkeypatch.setattr(results, "summaries", lambda: table)
    with pytest.raises(ConfigError, match=r"paper-stewart flies quiescent.*twin"):
        default_figures()
