import sys

from mrsteer_bench.run import main

sys.exit(main())
