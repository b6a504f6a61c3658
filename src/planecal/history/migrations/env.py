"""Alembic's environment for the history: the migrations run on the connection
``history.schema.alembic_config`` hands over, inside its open transaction (so a migration
and the backup's bookkeeping commit or roll back together). SQLite's ALTERs go through
Alembic's batch mode (a table copied), which its migrations ask for."""
from alembic import context

context.configure(connection=context.config.attributes["connection"],
                  render_as_batch=True)
with context.begin_transaction():
    context.run_migrations()
