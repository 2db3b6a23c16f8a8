"""The planner service: scan-location and route planning, locally and as a remote query."""
