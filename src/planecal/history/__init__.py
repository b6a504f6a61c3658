"""The cell's history: every calibrate, validate, export, check, compare and rollback
recorded with its provenance in one database (``store``; docs/HISTORY.md): where it is
(``place``), its tables and their migrations (``schema``, ``migrations/``; Alembic), how
each backend is opened (``backend``, ``opening``), its values checked in and out
(``values``). It knows nothing of the model: the commands build the entries
(``commands.history_options``), the statistics of check, compare and diff live in
``estimation.drift`` and ``estimation.agreement``, the tables in ``present.history``."""
from planecal.history.backend import HistoryError
from planecal.history.place import DEFAULT_FILE, ENV, location
from planecal.history.store import KINDS, Entry, History, InputRow, ParameterRow, consult
from planecal.history.values import check_label, clean

__all__ = ["DEFAULT_FILE", "ENV", "KINDS", "Entry", "History", "HistoryError", "InputRow",
           "ParameterRow", "check_label", "clean", "consult", "location"]
