"""``python -m microfacet``: the command line (see :mod:`microfacet.cli`)."""
from .cli import main

if __name__ == "__main__":
    raise SystemExit(main())
