"""The mission service: the mission supervisor."""
