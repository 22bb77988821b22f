"""The held-out seas: named scenario configs whose seas are NEVER used for fitting, training
or tuning anything in this project.

They measure whether estimates and landing decisions carry over to seas the project has not
seen: a bimodal swell plus wind sea (DNV-RP-C205 two-peak spectra), another heading, the ship
under way, and a sea state that changes during the episode, all built by
:mod:`landing_env.waves.generator` from the scenario's seed.  The episodes are the evaluation's
held-out seeds (``agents.evaluation.landing.HELD_OUT_SEED`` = 1 000 000 and on; the configs'
``seed`` is that first one), and the sea of each episode is a fixed function of its seed.

Rules (checked by ``tests/landing_env/sea/test_heldout.py``):

* no training config (``configs/train/*.yaml``) and no shipped fit (the deck-tilt
  predictors in ``landing_env/assets/predictors/``, the model cards in ``agents/models/``)
  names them;
* a model or predictor that is retrained, where one does not carry over, is retrained on a
  broader family of seas (:mod:`landing_env.sea.training_seas`), never on these.
"""

from __future__ import annotations

#: config name -> what it holds out (configs/<name>.yaml; each file's header says more)
HELD_OUT_SEAS: dict[str, str] = {
    "ship-unseen-4": (
        "ship deck, sea state 4 height: Ochi-Hubble wind sea (Tp 6.5 s) with a 13 s swell "
        "from the port bow, under way at 3 m/s, Hs 1.88 -> 2.4 m during the episode"
    ),
    "ship-unseen-5": (
        "ship deck, sea state 5 height: swell-dominated Torsethaugen sea (Tp 12 s) with the "
        "swell 50 deg off the wind sea, under way at 4 m/s, Hs 3.25 -> 3.8 m during the episode"
    ),
    "bench-unseen": (
        "Stewart bench: the scaled motion of a bimodal Ochi-Hubble sea (wind sea 6 s, beam "
        "swell 12 s), the stand-in vessel under way at 2 m/s, Hs 1.88 -> 2.5 m during the "
        "episode"
    ),
}
