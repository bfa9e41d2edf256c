import sys

from supportnode.cli import main

sys.exit(main())
