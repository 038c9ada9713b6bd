"""The command-line interface (the library never imports it)."""

from hapstab.cli.main import cli, main

__all__ = ["cli", "main"]
