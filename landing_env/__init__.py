"""deck-landing simulation: a quadrotor over a moving Stewart-platform deck (PyBullet)."""
