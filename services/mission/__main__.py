from common.service import run
from services.mission.config import MissionConfig
from services.mission.service import build

run("mission", MissionConfig, build)
