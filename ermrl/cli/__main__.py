import sys

from ermrl.cli import main

sys.exit(main())
