from common.service import run
from services.gnss.config import GnssConfig
from services.gnss.service import build

run("gnss", GnssConfig, build)
