from common.service import run
from services.planner.config import PlannerConfig
from services.planner.service import build

run("planner", PlannerConfig, build)
