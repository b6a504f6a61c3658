"""Subcommands of the planecal CLI (one module each)."""
