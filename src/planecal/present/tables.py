"""Plain text tables for the terminal, one way for every command and study."""
from __future__ import annotations


def table(headers: list[str], rows: list[list], aligns: str | None = None) -> str:
    """A plain text table; numbers should come pre-formatted as strings."""
    cells = [[str(c) for c in r] for r in rows]
    w = [max(len(h), *(len(r[i]) for r in cells)) if cells else len(h)
         for i, h in enumerate(headers)]
    aligns = aligns or ("l" + "r" * (len(headers) - 1))

    def fmt(r):
        return "  ".join(c.ljust(w[i]) if aligns[i] == "l" else c.rjust(w[i])
                         for i, c in enumerate(r))
    return "\n".join([fmt(headers), "  ".join("-" * x for x in w)] + [fmt(r) for r in cells])
