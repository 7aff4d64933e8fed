"""``python -m deepmorph``: the ``deepmorph`` command line."""

from deepmorph.cli import main

if __name__ == "__main__":
    main()
