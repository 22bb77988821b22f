"""``deck-landing list`` and ``deck-landing model``: their arguments (:mod:`agents.catalogue`)."""

from __future__ import annotations

import argparse

from agents.catalogue import ids_table, models_table, policies_table
from agents.cli_args import UserError
from agents.policy_registry import find_model
from agents.timing.cards import read_metadata

WHAT = ("ids", "policies", "models")


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
