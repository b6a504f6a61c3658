"""The history's schema migrations (Alembic): ``env.py`` runs them on the connection
``history.schema`` hands over; ``versions/`` holds one revision per schema version."""
