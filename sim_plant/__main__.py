import sys

from sim_plant.nodes.plant import main

sys.exit(main(prog="python -m sim_plant"))
