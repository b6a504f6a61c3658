"""planecal completion {bash,zsh,tcsh}: a shell completion script for planecal (shtab,
from the same parser the commands use), e.g.

    planecal completion bash > ~/.local/share/bash-completion/completions/planecal
    planecal completion zsh > "${fpath[1]}/_planecal"
"""
from __future__ import annotations


def add_arguments(p):
    p.add_argument("shell", choices=("bash", "zsh", "tcsh"), help="the shell")


def run(args) -> int:
    import shtab

    # cli.py hands its parser builder down (a command does not import the CLI above it)
    print(shtab.complete(args.full_parser(), shell=args.shell))
    return 0
