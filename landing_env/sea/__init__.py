"""The ship at sea: the helideck mount, the helideck monitoring system and its forecast, the
held-out seas and the training families of seas (the waves themselves: :mod:`landing_env.waves`)."""
