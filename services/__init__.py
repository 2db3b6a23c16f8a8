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
