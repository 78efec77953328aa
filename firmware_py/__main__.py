import sys

from firmware_py.runtime import main

sys.exit(main(prog="python -m firmware_py"))
