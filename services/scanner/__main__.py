from common.service import run
from services.scanner.config import ScannerConfig
from services.scanner.service import build

run("scanner", ScannerConfig, build)
