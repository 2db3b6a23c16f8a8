"""phenorover's services, one package each, all in the shape of ``services/gnss``.

``SERVICES`` maps a service name to its config type (lazily, ``module:attr``), so the
launcher can validate a whole manifest before it starts anything.
"""

SERVICES: dict[str, str] = {
    "sim": "services.sim.config:SimConfig",
    "gnss": "services.gnss.config:GnssConfig",
    "base": "services.base.config:BaseConfig",
    "scanner": "services.scanner.config:ScannerConfig",
    "nav": "services.nav.config:NavConfig",
    "planner": "services.planner.config:PlannerConfig",
    "mission": "services.mission.config:MissionConfig",
    "viz": "services.viz.config:VizConfig",
}

# Jobs: configured in a manifest like a service (``[services.register]``) but run on
# demand, by a command or by another service as a child process, so the launcher
# validates their sections and never starts them.
JOBS: dict[str, str] = {
    "register": "services.register.config:RegisterRunConfig",
}
