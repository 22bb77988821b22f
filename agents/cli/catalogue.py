"""``deck-landing list ids | policies | models`` and ``deck-landing model show``: what there
is, and what to use.

Each listing is built from its registry (:mod:`landing_env.scenarios`,
:mod:`agents.policies.registry`, the model cards in ``agents/models``), so it cannot disagree
with what the code runs.
"""

from __future__ import annotations

import argparse

from agents.common.cards import read_metadata
from agents.common.user_input import UserError
from agents.evaluation.results import Figure, recommended_figures
from agents.evaluation.summary import markdown_rows
from agents.policies.registry import DEFAULT_POLICY, MODEL_DIR, POLICIES, find_model
from landing_env.scenarios import SCENARIO_IDS, TASKS

WHAT = ("ids", "policies", "models")


def ids_table() -> str:
    """Every registered id: its task, scenario and what it builds."""
    rows = [
        (env_id, "task", "default", "the bare task on configs/default.yaml") for env_id in TASKS
    ]
    for env_id, entry in SCENARIO_IDS.items():
        status = f"superseded by {entry.superseded_by}" if entry.superseded_by else "current"
        rows.append((env_id, status, entry.scenario, entry.description))
    return markdown_rows(("id", "status", "scenario", "what it builds"), rows)


def recommendation_cell(figure: Figure) -> str:
    """``82.5 % (76.6-87.1) on 200 seeds from 5 000 000``."""
    return f"{figure.row.cell()} on {figure.result.seeds}"


def policies_table() -> str:
    """Every registered policy with its kind and status, then the recommendation per setting."""
    rows = []
    for spec in POLICIES.values():
        scenarios = ", ".join(spec.scenarios) or "all"
        defaults = ", ".join(
            f"{k}={v}"
            for k, v in (
                ("estimator", spec.estimator),
                ("sensing", spec.sensing),
                ("model", spec.model),
            )
            if v
        )
        rows.append(
            (spec.name, spec.kind, spec.status, spec.task, scenarios, defaults or "-", spec.summary)
        )
    text = markdown_rows(
        ("policy", "kind", "status", "task", "scenarios", "defaults", "what it does"), rows
    )
    recommended = [
        (
            figure.label,
            figure.policy,
            figure.result.scenario,
            figure.result.sensing,
            recommendation_cell(figure),
            figure.result.chosen_by or "-",
        )
        for figure in recommended_figures()
    ]
    text += "\n\nRecommended, setting by setting (reported on seeds held out from the choice):\n\n"
    text += markdown_rows(
        ("setting", "policy", "scenario", "sensing", "success (95% CI)", "chosen by"), recommended
    )
    defaults = ", ".join(f"{s}: {p}" for s, p in DEFAULT_POLICY.items())
    text += f"\n\n`evaluate landing --scenario S` without --policy runs: {defaults}."
    return text


def models_table() -> str:
    """Every shipped model with its card's id, estimator and sensing, and its policy."""
    by_model = {spec.model: spec for spec in POLICIES.values() if spec.model}
    rows = []
    for path in sorted(MODEL_DIR.glob("*.zip")):
        card = read_metadata(path)
        spec = by_model.get(path.name)
        policy = f"{spec.name} ({spec.status})" if spec else "svgs-routine's commit"
        if card is None:
            rows.append((path.name, policy, "no card", "", ""))
            continue
        rows.append(
            (path.name, policy, ", ".join(card.env_ids()), card.estimator, ", ".join(card.sensing))
        )
    return markdown_rows(("model", "policy", "trained on", "estimator", "sensing"), rows)


# ------------------------------------------------------------------------- the commands


def run_list(args: argparse.Namespace) -> int:
    print({"ids": ids_table, "policies": policies_table, "models": models_table}[args.what]())
    return 0


def add_list_parser(sub: argparse._SubParsersAction) -> None:
    """``deck-landing list ids|policies|models``."""
    listing = sub.add_parser(
        "list", help="the registered ids, the policies (with what to use) or the shipped models"
    )
    listing.add_argument("what", choices=WHAT)
    listing.set_defaults(func=run_list, sensors_act=False)


def run_model_show(args: argparse.Namespace) -> int:
    path = find_model(args.model)
    if not path.is_file():
        raise UserError(
            f"{args.model}: no such file, nor a shipped model (deck-landing list models)"
        )
    card = read_metadata(path)
    if card is None:
        print(f"{args.model} has no card (it was not trained by deck-landing)")
        return 1
    print(card.to_json())
    return 0


def add_model_parser(sub: argparse._SubParsersAction) -> None:
    """``deck-landing model show MODEL.zip``: a trained model's card."""
    model = sub.add_parser("model", help="a trained model's card (what it was trained on)")
    model.set_defaults(sensors_act=False)
    which = model.add_subparsers(dest="model_command", required=True)
    show = which.add_parser("show", help="print the card of a model zip")
    show.add_argument(
        "model", help="an SB3 zip: a path, or a name `deck-landing list models` prints"
    )
    show.set_defaults(func=run_model_show)


__all__ = [
    "add_list_parser",
    "add_model_parser",
    "ids_table",
    "models_table",
    "policies_table",
    "recommendation_cell",
]
