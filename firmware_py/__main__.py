import sys

from firmware_py.controller.main import main

sys.exit(main(prog="python -m firmware_py"))
