import sys

from vfactor.cli import main

sys.exit(main())
