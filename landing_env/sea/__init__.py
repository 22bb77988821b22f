"""The sea: wave spectra, a small vessel's motion in them, and the ship deck it carries."""
