"""Per-plot canopy traits of a registered survey (``phenorover traits RUN_DIR``).

Reads what registration left in a run folder (``registered.laz``, the mission log and
its plan's field), finds the ground with the cloth simulation filter (:mod:`.ground`),
cuts the cloud by every plot footprint and computes each plot's traits with the one
definition in :mod:`common.canopy` (:mod:`.compute`), and writes the field book of
traits as CSV, long CSV, GeoJSON and a field map (:mod:`.outputs`, :mod:`.fieldmap`).
Options: ``[services.traits]`` (:mod:`.config`). Pure computation, no bus; it reads
only what a real robot records, never a simulator's truth.
"""
