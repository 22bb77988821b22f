"""The waves and a vessel's motion in them: wave spectra (one and two peaks), the sea
generator, the sea's config, the ship's response and recorded deck motion; beneath the deck's
motion sources (:mod:`landing_env.stewart.motion`)."""
