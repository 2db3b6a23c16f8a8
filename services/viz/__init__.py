"""The viz service: the live rerun dashboard."""
