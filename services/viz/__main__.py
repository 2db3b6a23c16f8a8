from common.service import run
from services.viz.cli import VizCli
from services.viz.config import VizConfig
from services.viz.service import build

run("viz", VizConfig, build, options=VizCli(), lockstep="observer")
