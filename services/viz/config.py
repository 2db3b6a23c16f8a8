from typing import Annotated

import msgspec

from common.canopy import TRAITS
from common.messages.core import Positive, RobotName

Port = Annotated[int, msgspec.Meta(ge=0, le=65535)]
PosInt = Annotated[int, msgspec.Meta(gt=0)]


class VizConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The live rerun dashboard (docs/dashboard.md). Any combination of the three
    outputs (``serve``, ``save``, ``connect``) may be on."""

    robots: list[RobotName] = msgspec.field(default_factory=list)
    """The namespaces of robots sharing the field, each drawn under ``fleet/<namespace>/``
    (:mod:`services.viz.fleet_view`)."""
    serve: bool = False
    """Host rerun's gRPC server on ``bind``:``grpc_port`` and, unless ``web_port`` is 0,
    the web viewer on ``bind``:``web_port`` (served by rerun's CLI as a child process)."""
    bind: str = "0.0.0.0"
    """The address the server and the web viewer listen on."""
    grpc_port: Port = 9876
    """The gRPC server's port."""
    web_port: Port = 9090
    """The web viewer's port; 0: no web viewer."""
    advertise: str = ""
    """The host name browsers reach this machine by, put into the viewer link it logs;
    empty: ``bind``, or this machine's name when ``bind`` is 0.0.0.0."""
    server_memory_limit: str = "1GiB"
    """What the server keeps for viewers that connect late (oldest data goes first,
    static data stays)."""
    save: str = ""
    """An .rrd path to record into; ``{run_dir}`` and ``{mission}`` expand, and with
    ``{mission}`` each mission gets its own file, opened when the mission starts."""
    connect: str = ""
    """A viewer's URL (``rerun+http://HOST:9876/proxy``) to push into."""
    rate_hz: Annotated[float, msgspec.Meta(gt=0, le=60)] = 10.0
    """How often new robot and mission data are logged (wall time); newer messages
    replace older ones in between, so a slow viewer never slows the bus."""
    scan_points: PosInt = 20_000
    """Points kept per scan (a random subsample)."""
    registered_points: PosInt = 200_000
    """Points kept of the registered cloud (a random subsample)."""
    registered_files: list[str] = msgspec.field(
        default_factory=lambda: ["registered*.laz", "registered*.e57"]
    )
    """Globs, in the mission's run folder, of the registered cloud (LAZ in the field frame
    or a multi-scan E57 with poses)."""
    trail_step_m: Positive = 0.05
    """The driven trail's point spacing (m)."""
    trait: str = "height"
    """Which of :data:`common.canopy.TRAITS` the traits tab colours the plots by, once the
    mission's ``traits_file`` exists."""
    traits_file: Annotated[str, msgspec.Meta(min_length=1)] = "traits.csv"
    """The traits file in the mission's run folder (written after registration)."""

    def __post_init__(self) -> None:
        try:
            self.save.format(run_dir="r", mission="m")
        except (KeyError, IndexError, ValueError) as exc:
            raise ValueError(
                f"save={self.save!r}: only {{run_dir}} and {{mission}} expand ({exc!r})"
            ) from None
        if self.connect and not self.connect.startswith(("rerun://", "rerun+http")):
            raise ValueError(f"connect={self.connect!r}: expected rerun+http://HOST:PORT/proxy")
        if self.trait not in TRAITS:
            raise ValueError(f"trait={self.trait!r}: expected one of {', '.join(TRAITS)}")
