from common.service import run
from services.sim.config import SimCli, SimConfig
from services.sim.service import build

run("sim", SimConfig, build, options=SimCli(), lockstep="world")
