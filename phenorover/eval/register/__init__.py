"""``phenorover eval register RUN_DIR``: a registration scored against the simulator's
truth and set beside the paper's figures.

Registration (``services/register``) takes only what a real robot has and writes its
outputs: ``registered.e57`` (every scan in its scanner frame with its pose) and
``report.json`` (per scan its file, its poses by every method, its spheres and the
targets they were matched to). This package reads those outputs and, from the
simulator's ``<scan>.truth.json`` files (:mod:`.truth`), scores every method against
the true poses (:mod:`.score`); it sets our figures beside the paper's Table 1 and
Hausdorff figures (:mod:`.paper`); :mod:`.cli` writes ``eval_register.json`` and
``eval_register.md`` next to the report. :func:`.score.score_registration` scores an
in-memory registration the same way (the registration benchmark).
"""
