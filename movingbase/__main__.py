"""``python -m movingbase``: the command line (movingbase/cli.py)."""
from movingbase.cli import main

main()
