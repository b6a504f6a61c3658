"""One Alembic revision per schema version of the history (``history.schema``)."""
