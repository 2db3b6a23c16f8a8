from common.service import run
from services.viz.config import VizConfig
from services.viz.service import VizCli, build

run("viz", VizConfig, build, options=VizCli())
