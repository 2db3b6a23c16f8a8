from common.service import run
from services.nav.config import NavConfig
from services.nav.service import build

run("nav", NavConfig, build)
