"""stewart."""
