"""Registration of the scans of one survey (the future ``phenorover register RUN_DIR``).

Pure computation, no bus: place every scan with its navigation pose (paper eq. 1,
:mod:`common.poses`), refine all scans jointly cloud-to-cloud (:mod:`.refine`), solve
the target-based reference from the 200 mm spheres (:mod:`.spheres`, :mod:`.targets`),
score them against each other (:mod:`.metrics`), and write the registered E57 and a
merged LAZ (:mod:`common.pointcloud`). :func:`.pipeline.register` runs it all; its
options are the manifest's ``[services.register]`` (:mod:`.config`).

It uses only what a real robot has: the mission log (read-only, through
:mod:`common.missionlog`), the scans and the options. A simulator's truth is never
opened here: ``phenorover eval register`` (``phenorover/eval/register``) scores the outputs
against it.

Frames: scan points are in the ``scanner`` frame (x forward, z up, origin at the
optical centre); poses are 4x4 ``field <- scanner`` transforms; metres and radians.
"""
