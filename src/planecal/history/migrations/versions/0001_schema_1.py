"""Schema version 1: the history as issue 24 made it (no alembic_version of its own: a
version-1 history is stamped with this revision before it is upgraded).

Revision ID: 0001
Revises:
"""
import sqlalchemy as sa
from alembic import op

revision = "0001"
down_revision = None
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table("meta", sa.Column("key", sa.String(64), primary_key=True),
                    sa.Column("value", sa.Text, nullable=False))
    op.create_table(
        "entries",
        sa.Column("id", sa.Integer, primary_key=True, autoincrement=True),
        sa.Column("kind", sa.String(16), nullable=False),
        sa.Column("created_utc", sa.String(40), nullable=False),
        sa.Column("cell", sa.String(200)), sa.Column("scene", sa.Text),
        sa.Column("robot", sa.String(200)), sa.Column("robot_sha256", sa.String(64)),
        sa.Column("world", sa.Text), sa.Column("planecal_version", sa.String(40)),
        sa.Column("note", sa.Text), sa.Column("outcome", sa.String(32), nullable=False),
        sa.Column("exit_code", sa.Integer, nullable=False),
        sa.Column("against_id", sa.Integer, sa.ForeignKey("entries.id")),
        sa.Column("result_sha256", sa.String(64)), sa.Column("output", sa.Text),
        sa.Column("summary", sa.Text), sa.Column("document", sa.Text))
    op.create_index("entries_cell", "entries", ["cell"])
    op.create_index("entries_result", "entries", ["result_sha256"])
    op.create_table("inputs",
                    sa.Column("entry_id", sa.Integer, sa.ForeignKey("entries.id"),
                              nullable=False),
                    sa.Column("role", sa.String(40), nullable=False), sa.Column("path", sa.Text),
                    sa.Column("sha256", sa.String(64)), sa.Column("bytes", sa.Integer))
    op.create_index("inputs_entry", "inputs", ["entry_id"])
    op.create_table("parameters",
                    sa.Column("entry_id", sa.Integer, sa.ForeignKey("entries.id"),
                              nullable=False),
                    sa.Column("name", sa.String(40), nullable=False),
                    sa.Column("value", sa.Float, nullable=False), sa.Column("std", sa.Float),
                    sa.Column("unit", sa.String(20)), sa.Column("status", sa.String(60)))
    op.create_index("parameters_entry", "parameters", ["entry_id"])
    op.bulk_insert(sa.table("meta", sa.column("key"), sa.column("value")),
                   [{"key": "format", "value": "planecal-history"},
                    {"key": "schema_version", "value": "1"}])


def downgrade() -> None:
    for t in ("parameters", "inputs", "entries", "meta"):
        op.drop_table(t)
