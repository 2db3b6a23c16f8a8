"""The application on top of the services: the ``phenorover`` command (:mod:`.cli`),
the per-machine launcher (:mod:`.launcher`) and its preflight checks
(:mod:`.preflight`). It may import every service; nothing below imports it."""
