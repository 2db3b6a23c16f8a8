"""The application on top of the services: the ``phenorover`` command (:mod:`.cli`),
the per-machine launcher (:mod:`.launcher`, its watchdog for hung services
:mod:`.watchdog`), the checks run before anything starts (:mod:`.preflight`) and what
``up --check`` reports (:mod:`.findings`). It may import every service; nothing below imports it."""
