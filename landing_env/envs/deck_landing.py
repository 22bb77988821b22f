"""``DeckLanding-v1``: fly from a hover above the moving deck to a touchdown on it."""

from __future__ import annotations

from landing_env.envs.base import DeckLandingBaseEnv


class DeckLandingEnv(DeckLandingBaseEnv):
    """Land a quadrotor on a moving deck, steering by velocity set-points.

    .. rubric:: Description

    A quadrotor starts in a hover above a moving deck: a 6-DOF Stewart platform (the papers'
    bench, sea states 3-5 scaled into its workspace) or a 30 m vessel's helideck at sea
    (``deck_mount: ship``).  A downward camera sees an AprilTag on the deck and four
    time-of-flight (ToF) range sensors on the arms measure it; a camera+ToF estimator
    (``estimation.observed``: IHRCF in ``configs/default.yaml``; CRHF, ATDA, ``tight``,
    ``fused`` or ``truth``) turns them into the deck pose, and that estimate, not the ground
    truth, is what the agent observes.  Physics run at 240 Hz; one ``step`` is one control
    period of 50 ms (20 Hz, ``simulation.env_hz``), 12 physics sub-steps in which a PX4-style
    cascade controller (velocity, attitude, body rates, motor mixing) tracks the action.

    .. rubric:: Action space

    ``Box(-1, 1, (4,), float32)``: velocity set-points in the heading frame (the world frame
    turned by the drone's yaw: x forward, y left, z up), scaled by
    ``action.max_horizontal_speed`` (1.5 m/s), ``action.max_vertical_speed`` (1.0 m/s) and
    ``action.max_yaw_rate_deg`` (60 °/s) for (vx, vy, vz, yaw rate).  An action outside
    [-1, 1] is clipped and flagged in ``info["action_clipped"]``; one that is not a real,
    finite array of shape (4,) is refused with a ``ValueError``.

    .. rubric:: Observation space

    A ``Dict``:

    .. list-table::
       :header-rows: 1
       :widths: 18 14 46 22

       * - key
         - shape, dtype
         - meaning
         - frame, unit
       * - ``deck_pose``
         - (6,) float32
         - the deck (tag) pose as estimated: x, y, z, roll, pitch, yaw; zeros when invalid
         - camera frame C; m, rad (ZYX)
       * - ``deck_pose_valid``
         - (1,) float32
         - 1 when the estimate is valid (not: no tag, out of view, degenerate)
         -
       * - ``deck_pose_predicted``
         - (1,) float32
         - 1 when the corner tracker bridged a missed detection
         -
       * - ``tof_range``
         - (4,) float32
         - the four ToF ranges along the sensors' axes; 0 when invalid
         - m
       * - ``tof_valid``
         - (4,) float32
         - 1 when the reading is valid (a return within ``tof.max_range``)
         -
       * - ``imu``
         - (6,) float32
         - mean specific force (3) and angular rate (3) over the step, clipped to ±16 g and
           ±2000 °/s (``info["imu_saturated"]``)
         - body frame B; m/s², rad/s
       * - ``range_down``
         - (1,) float32
         - the downward rangefinder's range (to the deck, or the sea beside it); 0 when
           invalid
         - m
       * - ``range_down_valid``
         - (1,) float32
         - 1 when the rangefinder's reading is valid
         -
       * - ``velocity``
         - (3,) float32
         - the drone's velocity as its autopilot estimates it (PX4's
           ``vehicle_local_position``); the simulated controller flies on the true state, so
           it is the truth; clipped to ±30 m/s
         - heading frame H (x forward, y left, z up); m/s
       * - ``attitude``
         - (2,) float32
         - the drone's roll and pitch as its autopilot estimates them (``vehicle_attitude``)
         - world frame, ZYX; rad

    Every key is a float32 ``Box`` (the flags are 0 or 1), so SB3's ``VecNormalize`` and
    Gymnasium's ``FlattenObservation`` take the observation with their default arguments.
    The observation never holds NaN.  ``info`` carries the ground truth and diagnostics:
    ``deck_pose_true``, ``estimates`` (every configured estimator), ``drone``, ``deck``,
    ``imu_samples``, ``tof_ranges``, ``outcome`` and, after a touchdown, ``touchdown`` (its
    metrics).

    .. rubric:: Rewards

    With ``d = |Δxy| + w_v |Δz|`` the distance from the drone's centre to the tag centre
    (``reward.vertical_weight`` w_v = 0.5) and the potential ``Φ = -shaping_weight · d``,
    each step gives ``Φ(s') - Φ(s) - time_cost · Δt``; a crash subtracts ``crash_penalty``
    (10); a touchdown subtracts ``normal_speed_penalty · v_n + tilt_penalty · tilt_deg +
    offset_penalty · offset_m`` (4 per m/s, 0.2 per degree, 5 per metre), adds
    ``touchdown_bonus`` (5) for being on the deck, and a successful one adds
    ``success_bonus`` (10) more.  ``time_cost`` is 0.1 per second.  The shaping is
    potential-based, so it does not change the optimal policy.  A time-out is a truncation
    and carries no terminal term (the time cost has priced the hover), so that a learner
    bootstraps through it: 40 s of hovering (-4) is worth less than a successful touchdown
    (+15, less at most 2 for the normal speed and 1 for the tilt) and less than a touchdown
    up to about 1 m/s and 5° that fails (the touchdown bonus makes trying to land pay while
    a learner cannot land well yet; the success bonus then rewards landing well).  Each
    term is in ``info`` (``reward_shaping``, ``reward_time``, ``reward_success``,
    ``reward_touchdown``, ``reward_crash``, ``reward_normal_speed``, ``reward_tilt``,
    ``reward_offset``) and they sum to the reward.

    .. rubric:: Starting state

    The drone hovers ``start.height_m`` above the deck's home surface (1.8-2.2 m by default;
    the landing scenario ids 1.5-4 m), up to ``start.max_offset_m`` off its centre (0.3 m;
    the scenario ids 1 m) with ``|yaw|`` up to ``start.max_yaw_deg`` (10°; the scenario ids
    30°), drawn from the episode's seed.  The deck motion starts at a seeded phase.  The ship
    scenario ids (from ``-v3``) start in trim with the mean wind (``start.trim_to_wind``).

    .. rubric:: Episode end

    * **Touchdown** (terminated): at the first contact of a foot with the deck the metrics are
      taken (relative normal speed, deck tilt, drone-to-deck attitude, lateral offset), the
      motors idle and the simulation runs on for ``touchdown.settle_time_s`` (1 s).  Success
      when the relative normal speed is at most 0.5 m/s, the deck tilt at most 5°, the
      drone-to-deck attitude at most 10°, all four feet touched and the drone still stands on
      the deck after the settle without a bounce above 1 cm or a tip-over; otherwise the
      outcome is ``hard_landing`` with the failed checks listed.  Every threshold is a
      ``touchdown.*`` key.
    * **Crash** (terminated): any other contact (the body on anything, a foot off the deck), a
      flip beyond ``simulation.flip_tilt_deg``, or leaving the arena.
    * **Time-out** (truncated) after ``simulation.max_episode_s`` (30 s; the scenario ids
      40 s).

    .. rubric:: Arguments

    ``gym.make("DeckLanding-v1", config="default", render_mode=None, overrides=None,
    **sections)``: ``config`` is a shipped config name (``configs/*.yaml``) or a path;
    ``overrides`` sets dotted keys (``{"tof.noise": "vl53l1x"}``); a section keyword replaces
    keys of one section (``camera={"mode": "render"}``).  An unknown key or a bad value fails
    at construction with a ``ConfigError`` naming the key and what is allowed.
    ``render_mode="rgb_array"`` returns the camera image with the detections drawn;
    ``"human"`` opens the PyBullet window.  The scenario ids (``DeckLanding-BenchSS4-v1``,
    ``DeckLanding-ShipSS5-v4``, ...) build a shipped config with its landing overrides and
    take the same ``overrides``.

    .. rubric:: Version History

    * ``DeckLanding-v1`` (current): every observation key a float32 ``Box`` (the flags were
      ``MultiBinary``), the drone's own ``velocity`` and ``attitude`` observed, and a
      ``touchdown_bonus`` for any touchdown on the deck.  ``v0``:
      the task, any config; no longer registered (1.0.0).
    * ``DeckLanding-BenchSS{3,4,5}``, ``DeckLanding-PaperStewart``: the bench configs made a
      landing run (the drone flying, the tag projected, IHRCF observed); ``v1`` (current) has
      ``DeckLanding-v1``'s observation.
    * ``DeckLanding-HighApproach``: from 20 m up and 5 m off, in gusty wind, over a sea state
      3 deck with nested tags; ``v1`` (current) has ``DeckLanding-v1``'s observation.
    * ``DeckLanding-ShipSS{3,4,5,6}``: ``v1`` the ship decks, ``tight`` observed, the
      standard lens, started level and at rest with the bench's controller limits; ``v2`` the
      scenario's own lens (the wide 80° lens at sea states 5 and 6); ``v3`` started in trim
      with the mean wind, flying with the autopilots' stock limits (a 10 m/s² velocity
      integrator, 45° of tilt).  **v4** (current): ``DeckLanding-v1``'s observation.  v1-v3
      are no longer registered (1.0.0).
    """
