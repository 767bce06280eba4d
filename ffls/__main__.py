import sys

from ffls.cli import main

sys.exit(main())
