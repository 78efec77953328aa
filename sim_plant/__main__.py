import sys

from sim_plant.plant_node import main

sys.exit(main(prog="python -m sim_plant"))
