"""Registration of the scans of one survey (the future ``phenorover register RUN_DIR``).

Pure computation, no bus: place every scan with its navigation pose (paper eq. 1,
:mod:`.poses`), refine all scans jointly cloud-to-cloud (:mod:`.refine`), solve the
target-based reference from the 200 mm spheres (:mod:`.spheres`, :mod:`.targets`),
score them against each other and, in simulation, against the truth
(:mod:`.metrics`), and write the registered E57 and a merged LAZ (:mod:`.io`).
:func:`.pipeline.register` runs it all.

Frames: scan points are in the ``scanner`` frame (x forward, z up, origin at the
optical centre); poses are 4x4 ``field <- scanner`` transforms; metres and radians.
"""
