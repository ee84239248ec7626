"""Subcommands of the `predvla` console command."""
