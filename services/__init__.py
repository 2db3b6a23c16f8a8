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
    # device simulators for hardware-in-the-loop runs (deploy/hil.toml): each speaks its
    # device's own protocol on its own wire, so the hardware backends of gnss, base and
    # scanner drive the simulated robot unchanged
    "reach-sim": "services.gnss.sim.config:ReachSimConfig",
    "husky-sim": "services.base.sim.husky:HuskySimConfig",
    "faro-sim": "services.scanner.sim.config:FaroSimConfig",
}

# where a service's process lives when it is not ``services.<name>``
MODULES: dict[str, str] = {
    "reach-sim": "services.gnss.sim.reach",
    "husky-sim": "services.base.sim.husky",
    "faro-sim": "services.scanner.sim.faro",
}


def module_of(name: str) -> str:
    """The module ``python -m`` runs for service ``name``."""
    return MODULES.get(name, f"services.{name}")


# Jobs: configured in a manifest like a service (``[services.register]``) but run on
# demand, by a command or by another service as a child process, so the launcher
# validates their sections and never starts them.
JOBS: dict[str, str] = {
    "register": "services.register.config:RegisterRunConfig",
    "traits": "services.traits.config:TraitsConfig",
}
