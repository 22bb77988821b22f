"""The ship at sea: the helideck mount, the helideck monitoring system, the held-out seas and
the training families of seas (the waves themselves: :mod:`landing_env.waves`; the HMS's
forecast: :mod:`landing_env.anticipation.hms_forecast`)."""
