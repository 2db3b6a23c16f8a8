from common.service import run
from services.base.config import BaseConfig
from services.base.service import build

run("base", BaseConfig, build)
