import sys

from vibinverse.cli import main

sys.exit(main())
