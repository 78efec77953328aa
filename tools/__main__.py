import sys

from mrsteer_cli.cli import main

sys.exit(main())
