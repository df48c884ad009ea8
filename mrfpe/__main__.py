import sys

from mrfpe.cli import main

sys.exit(main())
