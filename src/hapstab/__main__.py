"""``python -m hapstab``: the command line."""

from hapstab.cli import main

if __name__ == "__main__":
    main()
