from common.service import run
from services.sim.config import SimConfig
from services.sim.service import build

run("sim", SimConfig, build)
