import sys

from sim_plant.harness.faults.cli import main

sys.exit(main())
