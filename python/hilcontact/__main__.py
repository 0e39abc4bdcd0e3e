"""``python -m hilcontact``: the command-line interface."""

from hilcontact.cli import main

if __name__ == "__main__":
    main()
