from typing import Annotated

import msgspec

from common.canopy import TRAITS
from common.messages.core import RobotName

Port = Annotated[int, msgspec.Meta(ge=0, le=65535)]
PosInt = Annotated[int, msgspec.Meta(gt=0)]


class VizConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The live rerun dashboard. Any combination of the three outputs may be on.

    ``serve``: host rerun's gRPC server on ``bind``:``grpc_port`` and, unless
    ``web_port`` is 0, the web viewer on ``bind``:``web_port`` (served by rerun's CLI
    as a child process). ``advertise`` is the host name browsers reach this machine by,
    put into the viewer link (default: ``bind``, or this machine's name when ``bind``
    is 0.0.0.0). ``server_memory_limit`` bounds what the server keeps for viewers that
    connect late (oldest data goes first, static data stays).
    ``save``: an .rrd path; ``{run_dir}`` and ``{mission}`` expand, and with
    ``{mission}`` each mission gets its own file, opened when the mission starts.
    ``connect``: a viewer's URL (``rerun+http://host:9876/proxy``) to push into.
    ``rate_hz``: how often new robot and mission data are logged (wall time); newer
    messages replace older ones in between, so a slow viewer never slows the bus.
    ``scan_points``/``registered_points``: points kept per scan / of the registered
    cloud (random subsample). ``registered_files``: globs, in the mission's run folder,
    of the registered cloud (LAZ in the field frame or a multi-scan E57 with poses).
    ``trait``: which of :data:`common.canopy.TRAITS` colours the plots once the
    mission's ``traits_file`` (in its run folder, written after registration) exists.
    ``robots``: the namespaces of robots sharing the field, each drawn under
    ``fleet/<namespace>/`` (:mod:`services.viz.fleet_view`).
    """

    robots: list[RobotName] = msgspec.field(default_factory=list)
    serve: bool = False
    bind: str = "0.0.0.0"
    grpc_port: Port = 9876
    web_port: Port = 9090
    advertise: str = ""
    server_memory_limit: str = "1GiB"
    save: str = ""
    connect: str = ""
    rate_hz: Annotated[float, msgspec.Meta(gt=0, le=60)] = 10.0
    scan_points: PosInt = 20_000
    registered_points: PosInt = 200_000
    registered_files: list[str] = msgspec.field(
        default_factory=lambda: ["registered*.laz", "registered*.e57"]
    )
    trail_step_m: Annotated[float, msgspec.Meta(gt=0)] = 0.05
    trait: str = "height"
    traits_file: Annotated[str, msgspec.Meta(min_length=1)] = "traits.csv"

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
