import sys

from ebraille_sim.cli import main

sys.exit(main())
