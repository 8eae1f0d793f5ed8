"""``python -m jaxsqueeze``: the same as the ``jaxsqueeze`` command."""
import sys

from .io.cli import main

if __name__ == "__main__":
    sys.exit(main())
