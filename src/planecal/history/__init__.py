"""The cell's history: every calibrate, validate, export, check, compare and rollback
recorded with its provenance in one database (``store``; docs/HISTORY.md). It knows
nothing of the model: the commands build the entries (``commands.history_options``), the
statistics of check, compare and diff live in ``estimation.drift`` and
``estimation.agreement``, the tables in ``present.history``."""
from planecal.history.store import (DEFAULT_FILE, ENV, KINDS, Entry, History, InputRow,
                                    ParameterRow, clean, location)

__all__ = ["DEFAULT_FILE", "ENV", "KINDS", "Entry", "History", "InputRow", "ParameterRow",
           "clean", "location"]
